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

"""Rebuild the summary of an MCAP recording whose recorder was killed (SIGKILL, power cut, full disk).

FILE may be one file or a recording's directory (every part that was not closed is recovered). Either way the
parts of the recording are listed as ``rubber-rig info`` lists them: which are missing, and how many samples.
"""
from pathlib import Path

from rubber_rig.recording import RecordingWriteError, recover
from rubber_rig.recording.mcapio import check_file, recording_files
from rubber_rig.recording.parts import survey

from .main import CommandError


def add_arguments(parser):
    parser.add_argument('file', help='MCAP file to recover, or a recording directory (its unclosed parts)')
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
    path = Path(args.file)
    if path.is_dir():
        if args.output:
            raise CommandError(f'{path} is a directory: its parts are recovered next to them (or --in-place), '
                               'not to one -o file')
        files = [f for f in recording_files(path) if not check_file(f)]
        if not files:
            print(f'{path}: every part was closed: nothing to recover')
        for f in files:
            _recover_one(args, f)
    else:
        _recover_one(args, path)
    for line in survey(path).lines():       # the same lines `rubber-rig info` prints
        print(f'parts: {line}')
    return 0


def _recover_one(args, path) -> None:
    try:
        result = recover(path, args.output, in_place=args.in_place, backup=not args.no_backup)
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
