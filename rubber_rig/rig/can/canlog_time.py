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

"""The time of a raw CAN log checked in file order: steps backwards and forward jumps, counted and named.

A log is written in time order (the rig's CanLogTap sorts within its reorder window; candump and CANoe write as
frames arrive), so a frame stamped earlier than the frame before it is an anomaly: a line moved or edited, two
logs concatenated, a clock stepped back (NTP) while logging. A hole of more than ``jump`` seconds with no frame
at all is one too on a rig bus, where the controller's heartbeat and status frames come several times a second
whenever it is powered: the logger paused, the clock stepped forward, or a stretch of the file is missing.

Nothing is reordered or dropped: the readers keep the frames in file order with their stamps as written, and
report each anomaly (kind, frame number, line number of a text log, the step) - decode_log in CanLog.warnings and
CanLog.time_anomalies, read_log (``conformance --log``) as a verdict about the log.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

JUMP_S = 10.0              # [s] a forward step larger than this between two frames is a jump
MAX_REPORTED = 10          # anomalies kept with their place (all of them are counted)
_WARNED = 3                # of those, named in the warning


@dataclass(frozen=True)
class TimeAnomaly:
    """One place where the log's time is not a plausible bus time.

    kind: 'backwards' (stamped before the frame preceding it in the file) or 'jump' (more than the jump limit after
    the latest frame before it); frame: 1-based number of the frame in file order; line: its line in a text log
    (None in BLF); t: its stamp [s, the log's time base]; step: [s] signed, against the preceding frame
    (backwards) or the latest stamp before it (jump).
    """

    kind: str
    frame: int
    line: int | None
    t: float
    step: float

    def text(self) -> str:
        where = f'frame {self.frame}' + (f' (line {self.line})' if self.line is not None else '')
        if self.kind == 'backwards':
            return f'{where}: time goes back {-self.step:.6g} s'
        return f'{where}: time jumps {self.step:.6g} s forward with no frame in between'

    def as_dict(self) -> dict:
        return asdict(self)


class TimeCheck:
    """Watches the stamps of a log's frames in file order (observe each one) and counts the anomalies.

    Parameters
    ----------
    jump : float
        [s] a gap with no frame longer than this is a jump (default JUMP_S).
    """

    def __init__(self, jump: float = JUMP_S):
        self.jump = float(jump)
        self.backwards = self.jumps = 0
        self.largest_back = 0.0            # [s] the largest step backwards (positive)
        self.anomalies: list[TimeAnomaly] = []   # the first MAX_REPORTED
        # frame numbers where the log's time series must be cut to measure intervals: every step back and every
        # forward step of more than `jump` against the frame before (the way back after a single displaced line)
        self.breaks: list[int] = []
        self._previous = self._latest = math.nan

    @property
    def count(self) -> int:
        return self.backwards + self.jumps

    def observe(self, t: float, frame: int, line: int | None = None) -> TimeAnomaly | None:
        """Check the stamp ``t`` [s] of frame number ``frame`` (line ``line`` of a text log); the anomaly or None."""
        found = None
        if math.isfinite(self._previous) and (t < self._previous or t - self._previous > self.jump):
            self.breaks.append(frame)
        if math.isfinite(self._previous) and t < self._previous:
            self.backwards += 1
            self.largest_back = max(self.largest_back, self._previous - t)
            found = TimeAnomaly('backwards', frame, line, t, t - self._previous)
        elif math.isfinite(self._latest) and t - self._latest > self.jump:
            self.jumps += 1
            found = TimeAnomaly('jump', frame, line, t, t - self._latest)
        if found is not None and len(self.anomalies) < MAX_REPORTED:
            self.anomalies.append(found)
        self._previous = t
        self._latest = t if not math.isfinite(self._latest) else max(self._latest, t)
        return found

    def summary(self) -> dict:
        """Counts and the first anomalies, JSON-able."""
        return {'time_backwards': self.backwards, 'time_jumps': self.jumps, 'jump_limit_s': self.jump,
                'largest_step_back_s': self.largest_back, 'time_anomalies': [a.as_dict() for a in self.anomalies]}

    def warning(self, path) -> str:
        """The warning of a log with anomalies ('' without any), naming the first ones by frame and line."""
        if not self.count:
            return ''
        named = '; '.join(a.text() for a in self.anomalies[:_WARNED])
        more = self.count - min(_WARNED, len(self.anomalies))
        parts = []
        if self.backwards:
            parts.append(f'goes backwards {self.backwards} time{"s" if self.backwards > 1 else ""} '
                         f'(at most {self.largest_back:.6g} s)')
        if self.jumps:
            parts.append(f'jumps forward {self.jumps} time{"s" if self.jumps > 1 else ""} by more than '
                         f'{self.jump:g} s')
        return (f'{path}: the log\'s time {" and ".join(parts)}: {named}' + (f' (and {more} more)' if more else '')
                + '; the frames are kept in file order with their stamps as written, so times and periods measured '
                'across these places are the log\'s, not the bus\'s')
