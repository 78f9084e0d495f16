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

"""What happened to a program's recording, for its goal's result, whatever else ended the program (ROS-free).

The excitation node feeds every recorder status (:class:`RecorderReport`, the fields of msg_defs/RecorderStatus
that matter, with the time it was received) to the :class:`RecordingOutcome` of the running program. The outcome
is one of:

- complete: a recorder status received after the program's last sample still records the same recording (a split
  into the next part, ``<name>_<i+1>.mcap``, is the same recording: parts.same_recording), with the samples the
  recorder counted lost during the program, if any;
- lost from (about) sample N, and why: the recorder's error (disk full, file too large, unwritable), the recorder
  gone (no status for ``timeout``, counted only while this node ran: StallWatch), stopped, or switched to another
  recording;
- not recorded: no recorder recorded the samples when the program started;
- not confirmed: the program ended and no recorder status came for ``timeout`` after it.

:meth:`RecordingOutcome.verdict` returns None while the answer is still pending (a program that just ended waits for
the next status, at most ``timeout``), so the node can hold the result that long.
"""
from __future__ import annotations

import errno
import math
from dataclasses import dataclass, field
from pathlib import Path

from .parts import same_recording

# words in a recorder's error that name the cause (the writer's messages: writer._guard)
_CAUSES = (('disk full', 'disk full'), ('file too large', 'file too large'), ('quota', 'disk quota exceeded'),
           ('cannot create', 'unwritable'), ('read-only', 'unwritable'), ('permission denied', 'unwritable'),
           (f'errno {errno.ENOSPC}', 'disk full'))


def cause_of(error: str) -> str:
    """The cause a recorder's error text names: 'disk full', 'file too large', 'unwritable', ... or 'write error'."""
    text = error.lower()
    return next((cause for key, cause in _CAUSES if key in text), 'write error')


@dataclass
class RecorderReport:
    """One recorder status as the outcome needs it. ``received``: when it came [s, this node's monotonic clock]."""

    received: float
    state: str                 # 'recording', 'idle', 'error'
    path: str = ''
    error: str = ''
    records_samples: bool = True   # the program's samples topic is among the recorder's matched topics
    samples_lost: int = 0


@dataclass
class RecordingOutcome:
    """The recording of one program (see the module doc). ``timeout`` [s]: a recorder without a status for this long
    is gone.
    """

    timeout: float
    topic: str = ''
    recorded_by: str = ''       # the file the program started being recorded in ('' if none)
    parts: list = field(default_factory=list)   # the files it was recorded in (a split adds one)
    lost: str = ''              # why it was lost, in words ('' if it was not)
    lost_from: int | None = None
    cause: str = ''             # 'disk full', 'recorder gone', 'stopped', ...
    latest: RecorderReport | None = None
    lost_at_start: int = 0

    def start(self, report: RecorderReport | None, now: float, since: float = -math.inf) -> None:
        """The program starts at ``now`` with ``report`` the latest recorder status (None: never one); ``since``:
        when this node last resumed from a stall of its own (StallWatch.resumed_at).
        """
        self.latest = report
        fresh = report is not None and now - max(report.received, since) <= self.timeout
        if fresh and report.state == 'recording' and report.records_samples and report.path:
            self.recorded_by, self.parts = report.path, [report.path]
            self.lost_at_start = report.samples_lost

    def _lose(self, sample: int, cause: str, why: str) -> None:
        self.lost_from, self.cause = sample, cause
        self.lost = (f'recording lost from about sample {sample}: {cause}: {why}; the samples after it are not in '
                     f'{self.where()}')

    def where(self) -> str:
        if len(self.parts) > 1:
            return f'{Path(self.parts[0]).parent} (parts {Path(self.parts[0]).name}..{Path(self.parts[-1]).name})'
        return self.recorded_by

    def observe(self, report: RecorderReport, next_sample: int, measured: bool = True) -> str:
        """A recorder status while the program runs (``next_sample``: the next sample it expects; ``measured``:
        False before its first sample was measured). Returns the loss text if this status revealed it ('' otherwise).
        """
        self.latest = report
        if not measured and report.state == 'recording' and report.records_samples and report.path:
            # nothing of the program was measured yet: it is recorded where the recorder records now (the status it
            # started with may have been a replaced recorder's last)
            if not self.recorded_by:
                self.lost_at_start = report.samples_lost
            self.recorded_by, self.parts = report.path, [report.path]
            return ''
        if not self.recorded_by or self.lost:
            return ''
        if report.state == 'error':
            self._lose(next_sample, cause_of(report.error), f'the recorder failed: {report.error or "error"}')
        elif report.state != 'recording' or not report.records_samples:
            self._lose(next_sample, 'stopped', f'the recorder is {report.state}'
                       + ('' if report.records_samples else f' without {self.topic or "the samples"}'))
        elif report.path and report.path != self.parts[-1]:
            if same_recording(self.parts[-1], report.path):
                self.parts.append(report.path)       # a split: the same recording goes on in its next part
                return ''
            self._lose(next_sample, 'switched', f'the recorder switched to another recording, {report.path}')
        return self.lost

    def check(self, now: float, next_sample: int, since: float = -math.inf) -> str:
        """The recorder is gone if no status came for ``timeout``, counted from ``since`` (this node's last resume)
        if that is later. Returns the loss text if this check revealed it ('' otherwise).
        """
        if not self.recorded_by or self.lost or self.latest is None:
            return ''
        age = now - max(self.latest.received, since)
        if age > self.timeout:
            self._lose(next_sample, 'recorder gone', f'no recorder status for {age:.1f} s (the recorder is gone)')
            return self.lost
        return ''

    def _records_it(self, report: RecorderReport) -> bool:
        """``report`` says the recorder still records this program's recording (a later part of it counts)."""
        return (report.state == 'recording' and report.records_samples
                and (report.path in self.parts or same_recording(self.parts[-1], report.path)))

    def verdict(self, now: float, end_sample: int, ended: float, since: float = -math.inf,
                heard: float | None = None, wait: float = 0.75) -> str | None:
        """The result's words on the recording of a program that ended at ``ended`` [s] with ``end_sample`` the
        sample after its last; None while word from the recorder may still come (at most ``wait`` [s] after the
        end, counted while this node ran). Complete takes a recorder status received after the end that records
        the recording, or the recorder's heartbeat received after the end (``heard``) with a status at most ``wait``
        before the end that records it.
        """
        if not self.recorded_by:
            return ('no recording: no recorder was recording ' + (self.topic or 'the samples')
                    + ' when the program started')
        if self.lost:
            return self.lost
        last = self.latest
        if last is not None and self._records_it(last) and (
                last.received > ended or (heard is not None and heard > ended and last.received >= ended - wait)):
            lost = last.samples_lost - self.lost_at_start
            return (f'recording complete in {self.where()}' + (
                f' ({lost} samples lost in transport or writing, counted by the recorder and in the file)'
                if lost > 0 else ''))
        if last is not None and last.received > ended and last.state == 'error':
            self._lose(end_sample, cause_of(last.error), f'the recorder failed at the end: {last.error}')
            return self.lost
        waited = now - max(ended, since)
        if waited > wait:
            age = now - max(last.received if last is not None else -math.inf, since)
            self.cause = 'recorder gone'
            return (f'recording not confirmed to the end (recorder gone?): no word from the recorder for '
                    f'{waited:.1f} s after the program ended (its last status {age:.1f} s ago); {self.where()} may '
                    f'end before sample {end_sample}')
        return None
