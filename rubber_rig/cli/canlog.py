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

"""Decode a raw CAN log (.blf, .asc, candump .log) of the rig with the project's DBC: summary, optional CSV.

Examples:
  rubber-rig canlog /tmp/rig.blf
  rubber-rig canlog /tmp/rig.log --json
  rubber-rig canlog /tmp/rig.asc -o samples.csv
The log is what rig_driver writes with the parameter can_log (or any capture of the rig's bus, e.g.
`candump -L can0`). The CSV has one row per measured sample (Feedback frame), in SI units.
In a damaged .asc or .log an unreadable line (not text, not a frame line, a frame cut short) is skipped and
the frames before and after it are decoded: the summary gives the count of skipped lines ('bad lines:', JSON
lines_skipped) and the first ones by number with the reason. A log with no readable frame is refused (exit 2).
A log cut short (ends inside a line or record) is reported as truncated ('truncated:', JSON truncated). A frame
stamped before the frame preceding it, or a hole of more than 10 s without frames, is a time anomaly of the log
('time:', JSON time_backwards / time_jumps / time_anomalies with frame and line numbers); the frames are kept
in file order with their stamps as written, and a warning says so. --recording DIR compares the log with the
MCAP recording of the same run: samples in both (values to the DBC resolution), only in one of them, the offset of
the recording's stamps from the log's time (with the log's time anomalies named, never taken for the rig's clock).
"""
import csv
import datetime
import json
import math
import sys
import warnings

from rubber_rig.recording import RecordingError, load_recording
from rubber_rig.rig.can.canlog import SUPPORTED_FORMATS
from rubber_rig.rig.can.canlog_compare import compare_with_recording, comparison_lines
from rubber_rig.rig.can.canlog_reader import decode_log
from rubber_rig.rig.can.protocol import Protocol
from rubber_rig.rig.config import RigConfig

from .main import CommandError

_DEFAULTS = RigConfig()
CSV_COLUMNS = (('sequence', 'sequence'), ('time_s', 'time'), ('time_ns', 'time_ns'),
               ('displacement_m', 'displacement'), ('force_N', 'force'), ('setpoint_m', 'setpoint'),
               ('temperature_degC', 'temperature'), ('status', 'status'))


def add_arguments(parser):
    parser.add_argument('log', help='raw CAN log: .blf (Vector BLF), .asc (Vector ASC) or .log (candump -L)')
    parser.add_argument('--json', action='store_true', help='machine-readable summary')
    parser.add_argument('-o', '--output', help='write the decoded samples as CSV to this file')
    parser.add_argument('--recording', help='compare with the MCAP recording (file or directory) of the same run')
    parser.add_argument('--bitrate', type=float, default=float(_DEFAULTS.bitrate),
                        help='arbitration bit rate for the bus load estimate [bit/s] (default %(default)g)')
    parser.add_argument('--data-bitrate', type=float, default=float(_DEFAULTS.data_bitrate),
                        help='CAN FD data bit rate for the bus load estimate [bit/s] (default %(default)g)')


def check_arguments(args):
    """Option values argparse cannot check; a message here is a usage error (exit 2)."""
    for name in ('bitrate', 'data_bitrate'):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            return f'argument --{name.replace("_", "-")}: must be a positive number of bit/s, got {value:g}'
    return None


def _range(a):
    return [int(a[0]), int(a[-1])] if len(a) else None


def summary(log, bitrate: float, data_bitrate: float) -> dict:
    """The summary of a decoded CanLog as a JSON-able dict."""
    load = log.bus_load(bitrate, data_bitrate)
    start = (datetime.datetime.fromtimestamp(log.start, datetime.timezone.utc).isoformat()
             if math.isfinite(log.start) else None)
    return {
        'log': log.path, 'format': log.format, 'complete': log.complete, 'warnings': log.warnings,
        'start': start, 'start_timestamp': log.start if math.isfinite(log.start) else None,
        'duration_s': log.duration, 'channels': [str(c) for c in log.channels],
        'frames_total': log.frames_total, 'frames_rx': log.frames_rx, 'frames_tx': log.frames_tx,
        'frames': dict(sorted(log.frames.items(), key=lambda kv: -kv[1])),
        'frames_by_id': {f'0x{k:03x}': v for k, v in log.frames_by_id.items()},
        'frames_malformed': log.frames_malformed, 'frames_unknown': log.frames_unknown,
        'error_frames': log.error_frames, 'frames_late': log.frames_late,
        'lines_skipped': log.lines_skipped, 'truncated': log.truncated,
        'time_ok': log.time_ok, 'time_backwards': log.time_backwards, 'time_jumps': log.time_jumps,
        'time_anomalies': [a.as_dict() for a in log.time_anomalies],
        'skipped_lines': [{'line': n, 'why': why} for n, why in log.skipped_lines],
        'samples': len(log), 'sequence': _range(log.sequence),
        'setpoints': int(log.setpoint_sequence.size), 'setpoint_sequence': _range(log.setpoint_sequence),
        'sequence_gaps': len(log.gaps), 'samples_lost': log.samples_lost, 'gaps': log.gaps[:20],
        'jumps': log.jumps[:20],
        'states': [{'time_s': t, 'state': s} for t, s in log.states[:50]],
        'faults_seen': log.faults_seen,
        'commands': [{'time_s': t, 'command': c, 'argument_m': a} for t, c, a in log.commands[:50]],
        'bus_load': load if math.isfinite(load) else None, 'bitrate': bitrate, 'data_bitrate': data_bitrate,
    }


def _write_csv(log, path):
    with open(path, 'w', newline='', encoding='utf-8') as f:
        w = csv.writer(f)
        w.writerow([name for name, _ in CSV_COLUMNS])
        columns = [getattr(log, attr).tolist() for _, attr in CSV_COLUMNS]
        for row in zip(*columns, strict=True):
            w.writerow([repr(v) if isinstance(v, float) else v for v in row])


def _print(info, log):
    state = 'complete' if log.complete else 'INCOMPLETE (see the warnings)'
    print(f'log:        {info["log"]} ({SUPPORTED_FORMATS[log.format]}), {state}')
    for text in log.warnings:
        print(f'WARNING:    {text}')
    print(f'start:      {info["start"] or "-"}  channel {", ".join(info["channels"]) or "-"}')
    print(f'duration:   {info["duration_s"]:.3f} s')
    print(f'frames:     {info["frames_total"]} ({info["frames_rx"]} rx, {info["frames_tx"]} tx)')
    ids = {m.name: m.frame_id for m in Protocol().db.messages}
    for name, count in info['frames'].items():
        rate = count / info['duration_s'] if info['duration_s'] > 0 else math.nan
        fid = ids.get(name)
        print(f'  {name:<22} {"" if fid is None else f"0x{fid:03x}":<6} {count:>9}  {rate:10.1f}/s')
    if info['samples']:
        print(f'samples:    {info["samples"]} (Feedback), sequence {info["sequence"][0]}..{info["sequence"][1]}')
    else:
        print('samples:    none')
    if info['setpoints']:
        print(f'setpoints:  {info["setpoints"]} sent, sequence {info["setpoint_sequence"][0]}..'
              f'{info["setpoint_sequence"][1]}')
    jumps = f' ({len(log.jumps)} jumps of an idle rig to a new stream, not loss)' if log.jumps else ''
    print(f'gaps:       {info["sequence_gaps"]} sequence gaps, {info["samples_lost"]} samples lost{jumps}')
    for gap in log.gaps[:20]:
        print(f'  at {gap["time"]:.3f} s: expected {gap["expected"]}, got {gap["received"]} ({gap["lost"]} lost)')
    print(f'bad frames: {log.frames_malformed} malformed (length/CRC), {log.frames_unknown} unknown identifier, '
          f'{log.error_frames} error frames, {log.frames_late} late or duplicated')
    anomalies = f'{log.time_backwards} steps backwards, {log.time_jumps} jumps forward'
    print(f'time:       {"monotonic" if log.time_ok else "NOT MONOTONIC: " + anomalies} (frames kept in file order)')
    for a in log.time_anomalies:
        print(f'  {a.text()}')
    if log.truncated:
        print('truncated:  yes: the file ends inside a line or record (cut short, or its writer never closed it)')
    if log.format != '.blf':   # text logs are read line by line; an unreadable line is skipped
        print(f'bad lines:  {log.lines_skipped} unreadable lines skipped (the frames around them are decoded)')
        for n, why in log.skipped_lines:
            print(f'  line {n}: {why}')
        if log.lines_skipped > len(log.skipped_lines):
            print(f'  ... and {log.lines_skipped - len(log.skipped_lines)} more')
    states = ', '.join(f'{s} {t:.3f} s' for t, s in log.states[:12]) + (' ...' if len(log.states) > 12 else '')
    print(f'states:     {states or "-"}')
    print(f'faults:     {", ".join(log.faults_seen) or "none"}')
    if log.commands:
        more = ' ...' if len(log.commands) > 8 else ''
        cmds = ', '.join(f'{c} {t:.3f} s' for t, c, _ in log.commands[:8]) + more
        print(f'commands:   {cmds}')
    if info['bus_load'] is not None:
        note = ' (faster than a real bus: an unpaced simulated run?)' if info['bus_load'] > 1 else ''
        print(f'bus load:   {info["bus_load"] * 100:.1f} % estimated at {info["bitrate"] / 1e6:g} Mbit/s, '
              f'{info["data_bitrate"] / 1e6:g} Mbit/s data, without bit stuffing{note}')


def run(args) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')   # decode_log's warnings are printed below, in the summary
        log = decode_log(args.log)
    info = summary(log, args.bitrate, args.data_bitrate)
    if args.output:
        _write_csv(log, args.output)
        info['csv'] = args.output
    comparison = None
    if args.recording:
        try:
            rec = load_recording(args.recording, allow_truncated=True)
        except RecordingError as exc:
            raise CommandError(str(exc)) from None
        comparison = info['recording_comparison'] = compare_with_recording(log, rec)
    if args.json:
        print(json.dumps(info, indent=2, default=str))
    else:
        _print(info, log)
        if args.output:
            print(f'csv:        {args.output} ({len(log)} samples)')
        if comparison is not None:
            print(f'recording:  {args.recording}')
            for line in comparison_lines(comparison):
                print(line)
    if not log.complete:
        n = log.lines_skipped
        what = (f'skipped {n} unreadable line{"" if n == 1 else "s"}, decoded the frames before and after them'
                if n else 'decoded what precedes the damage')
        if log.truncated:
            what += '; the log is truncated (cut short or never closed)'
        print(f'rubber-rig canlog: warning: {args.log} is incomplete: {what} (see the warnings)', file=sys.stderr)
    if not log.time_ok:
        print(f'rubber-rig canlog: warning: the time of {args.log} goes backwards {log.time_backwards} times and '
              f'jumps forward {log.time_jumps} times (see the warnings)', file=sys.stderr)
    return 0
