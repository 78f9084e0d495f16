# Copyright 2026 rubber_rig developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Create or check the rig's secret key (authenticated commands and samples; README "Who may move the rig").

``rubber-rig keys init [--path FILE] [--force]`` writes a new random key (mode 0600) to FILE (default:
$RUBBER_RIG_KEY_FILE, else ~/.config/rubber_rig/rig.key); every node of the rig and every client that commands it
(rubber-rig bench, scripts) must read the same file (node parameter ``auth.key_file``, or the environment
variable). ``rubber-rig keys check [--path FILE]`` says whether the file is a usable key (exit 2 if not). The key
is never printed and never sent: only signatures made with it travel.
"""
from __future__ import annotations

import argparse

from rubber_rig.security import KeyFileError, default_key_path, init_key, load_key


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('action', choices=('init', 'check'), help='init: create a new key file; check: test one')
    parser.add_argument('--path', help='key file (default: $RUBBER_RIG_KEY_FILE, else ~/.config/rubber_rig/rig.key)')
    parser.add_argument('--force', action='store_true', help='init: replace an existing key (every node and client '
                        'then needs the new one)')


def run(args) -> int:
    path = args.path or default_key_path()
    if args.action == 'init':
        try:
            written = init_key(path, overwrite=args.force)
        except FileExistsError as exc:
            raise ValueError(str(exc)) from None
        print(f'key written to {written} (mode 0600); give its path to every node (auth.key_file) and client '
              '(RUBBER_RIG_KEY_FILE or --key-file)')
        return 0
    try:
        load_key(path)
    except KeyFileError as exc:
        raise ValueError(str(exc)) from None
    print(f'{path}: a usable key (mode 0600)')
    return 0
