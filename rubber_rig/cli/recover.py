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

"""Rebuild the summary of an MCAP recording whose recorder was killed (SIGKILL, power cut, full disk)."""
from rubber_rig.recording import RecordingWriteError, recover

from .main import CommandError


def add_arguments(parser):
    parser.add_argument('file', help='MCAP file to recover')
    where = parser.add_mutually_exclusive_group()
    where.add_argument('-o', '--output', help='output file (default: <name>.recovered.mcap)')
    where.add_argument('--in-place', action='store_true',
                       help='replace FILE by the recovered file (the original is kept as FILE.bak)')
    parser.add_argument('--no-backup', action='store_true', help='with --in-place: keep no .bak')


def check_arguments(args):
    """Option combinations argparse cannot express; a message here is a usage error (exit 2)."""
    if args.no_backup and not args.in_place:
        return 'argument --no-backup: only allowed with argument --in-place (without it FILE is never replaced)'
    return None


def run(args) -> int:
    try:
        result = recover(args.file, args.output, in_place=args.in_place, backup=not args.no_backup)
    except RecordingWriteError as exc:     # the output cannot be written: the input is fine, the job failed
        raise CommandError(str(exc)) from None
    # a damaged input raises RecordingError (bad input, exit 2) naming the record and its offset: nothing written
    if result.summary_error:
        state = f'had a damaged summary section ({result.summary_error}); its data section is intact'
    elif result.was_complete:
        state = 'was already complete'
    else:
        state = f'was truncated (intact data ends at byte {result.intact_end} of {result.size})'
    print(f'{result.source} {state}; wrote {result.output}: {result.messages} messages on '
          f'{result.channels} topics, {result.metadata_records} metadata records')
    # the loss as the ledger counts it (the recorder and `rubber-rig info` count the same way); the tail of a
    # truncated file is unknown: said so, never a bare '0 lost'
    print(result.loss_text())
    return 0
