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

"""The terminal view of ``rubber-rig bench``: table rows scroll, the progress line is rewritten in place."""
from __future__ import annotations

import math
import shutil
import sys
import time


class Terminal:
    """Table rows scroll; the progress line is rewritten in place on a terminal (printed every few s otherwise)."""

    def __init__(self, quiet: bool):
        self.tty = sys.stdout.isatty() and not quiet
        self.quiet = quiet
        self._last_plain = 0.0
        self._status = ''

    def line(self, text: str) -> None:
        if self.tty and self._status:
            sys.stdout.write('\r' + ' ' * min(len(self._status), shutil.get_terminal_size().columns - 1) + '\r')
        print(text, flush=True)
        if self.tty and self._status:
            sys.stdout.write(self._status)
            sys.stdout.flush()

    def status(self, text: str) -> None:
        if self.quiet:
            return
        width = shutil.get_terminal_size().columns - 1
        if self.tty:
            self._status = text[:width]
            sys.stdout.write('\r' + self._status.ljust(width)[:width] + '\r' + self._status)
            sys.stdout.flush()
        elif time.monotonic() - self._last_plain >= 5.0:
            self._last_plain = time.monotonic()
            print(text, flush=True)

    def end_status(self) -> None:
        if self.tty and self._status:
            sys.stdout.write('\n')
            self._status = ''


def progress_text(fb, stats, t_start) -> str:
    achieved = '--' if math.isnan(fb.achieved_amplitude) else f'{fb.achieved_amplitude * 1e3:.3f}'
    return (f'[{fb.progress * 100:5.1f}%] block {fb.block_index + 1}/{fb.block_count} {fb.block_name}  '
            f'cycle {fb.cycle}/{fb.cycles_total}  A {fb.target_amplitude * 1e3:.3f} mm -> {achieved} mm  '
            f'| {stats.samples} samples, {stats.gaps} gaps | {time.monotonic() - t_start:5.1f} s')


def print_result(summary: dict, rec_loss: dict, recording_error: str, paced: bool, mcap, jpath, mpath,
                 summary_error: str) -> None:
    """The closing lines of a bench run: result, loss, latency and where the recording and summary are."""
    live = summary['loss']['live']
    wall = summary['wall_time_s']
    print(f"\nprogram: {summary['result']['message']} ({wall:.1f} s)")
    print(f"samples: {live['samples']['samples']} published, {live['samples']['gaps']} gaps; "
          f"predictions: {live['prediction']['samples']}, {live['prediction']['gaps']} gaps; "
          f"recording: {rec_loss.get('samples_lost', 'n/a')} samples lost"
          + (f" ({rec_loss['samples_not_recorded']} published samples not recorded)"
             if rec_loss.get('samples_not_recorded') else ''))
    events = summary.get('events', [])
    print(f'detector events: {len(events)}' + ''.join(f"\n  {e['action']}: {e['message']}" for e in events))
    if recording_error:
        print(f'RECORDING FAILED: {recording_error}')
    lat, first = summary['latency'].get('last_sample'), summary['latency'].get('first_sample')
    if lat and first:
        # first sample of a batch: includes waiting for the batch to fill; last sample: the pipeline alone
        print(f"latency sample -> prediction: last sample of a batch median {lat['median_ms']:.2f} ms, "
              f"p99 {lat['p99_ms']:.2f} ms; first sample median {first['median_ms']:.2f} ms, "
              f"p99 {first['p99_ms']:.2f} ms ({lat['count']} batches)")
    elif not paced:
        print('latency: not measured with --fast (rig time runs ahead of the wall clock)')
    print(f'MCAP recording: {mcap}' + ('' if rec_loss.get('complete', True) else
                                       ' (not closed: readable up to its last complete chunk)'))
    if summary_error:
        print(f'summary:        NOT WRITTEN ({summary_error}); printed above as JSON')
    else:
        print(f'summary:        {jpath}')
        print(f'                {mpath}')
