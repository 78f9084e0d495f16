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

"""A scenario's FAIL in a stretch where this host was late enough to explain it is *not judged* (docs/protocol.md,
"Host timing"; issue 36).

A scenario acts on the run's view of the controller (its position, state, next sequence) and on time: it sends
a stream LEAD ahead, waits 100 ms for an answer, 0.2 s for RESET to take. When this host kept the run, or the
simulator standing for the controller, from a CPU, the view lags and the stream or the reaction is late - on a
2-core host under load by hundreds of ms - and what the scenario then saw is not the controller's doing. Every
FAIL a scenario puts keeps the Stretch of the run it judged (report.Results.put: explicit, or the scenario so far);
at the end of the run, with every source of lateness merged in, a FAIL is not judged when in *each* of its stretches

- this host was late without a break (host_timing.longest_late, any source) for at least the requirement's own
  time tolerance (TIME_TOLERANCE: the time the requirement or its scenario gives, e.g. 100 ms for IDENTIFY), or
- the violation is itself a time (a ramp that took too long) and this host was late within the stretch, all
  delays together (host_timing.late_total), for at least its excess over the bound.

Lateness shorter than that cannot have changed the verdict, and the FAIL stands; a FAIL with no stretch (the
checks of the whole trace, which have their own rules) and the requirements on values rather than times (the
rated velocity, measured values: TIME_TOLERANCE None) are never excused. On a quiet host nothing is recorded and
every defect fails as before.
"""
from __future__ import annotations

from .host_timing import late_total, longest_late, not_judged
from .link import DEFAULT_HOST_TIMEOUT, LEAD, REACTION, RESET_TIME
from .report import FAIL, NOT_TESTED

#: requirement id -> (time tolerance [s], what it is): a delay of this host this long in a FAIL's stretch can
#: have made it; requirements not listed (trace checks, CTRL-ID-1 and CTRL-WD-1 with rules of their own that
#: weigh the lateness against the violation, values) are never excused here. A verdict whose violation no delay
#: can make (a setpoint applied beyond a limit, a fault that clears itself) or that is a time (a ramp too long, no
#: ramp at all) gives its stretch an infinite tolerance: only lateness of its excess, if any, then explains it
TIME_TOLERANCE = {
    'CTRL-PWR-1': (REACTION, 'the time a controller is given to react'),
    'CTRL-STREAM-1': (LEAD, 'how far ahead the run streams: a longer delay underruns the stream'),
    'CTRL-STREAM-2': (LEAD, 'how far ahead the run streams'),
    'CTRL-STREAM-3': (LEAD, 'how far ahead the run streams: a longer delay sends a setpoint after its tick'),
    'CTRL-RAMP-1': (REACTION, 'the time a ramp may take beyond its nominal duration x 1.5'),
    'CTRL-RAMP-2': (REACTION, 'the time a controller is given to react'),
    'CTRL-RESET-1': (LEAD, 'how far ahead the run streams: a longer delay underruns the stream'),
    'CTRL-FRAME-2': (LEAD, 'how far ahead the run streams: a longer delay underruns the stream'),
    'CTRL-FRAME-3': (LEAD, 'how far ahead the run streams: a longer delay underruns the stream'),
    'CTRL-LIM-1': (REACTION, 'the wait beyond LEAD before the ABORT that must stop at the limit'),
    'CTRL-LIM-2': (REACTION, 'the time a controller is given to react'),
    'CTRL-LIM-3': (REACTION, 'the time a controller is given to react'),
    'CTRL-FAULT-1': (DEFAULT_HOST_TIMEOUT, 'the host timeout the controller states (this where it states none): a '
                     "longer silence of this host trips the controller's watchdog, another fault bit"),
    'CTRL-FAULT-2': (RESET_TIME, 'the time RESET is given to return to idle'),
}


def explained(windows, stretch, tolerance: float) -> float:
    """This host's lateness [s] that explains a FAIL in `stretch` (report.Stretch), 0 if it does not: the longest
    delay without a break when at least `tolerance` [s], else, for a violation that is a time, all of the delays
    in the stretch when at least its excess.
    """
    longest = longest_late(windows, stretch.t0, stretch.t1)
    if longest > 0 and longest >= tolerance:
        return longest
    if stretch.excess is not None and stretch.excess > 0:
        total = late_total(windows, stretch.t0, stretch.t1)
        if total >= stretch.excess:
            return total
    return 0.0


def excuse(results, windows, origin: float = 0.0) -> list:
    """Make every scenario FAIL of `results` (report.Results) that this host's lateness `windows` [(start, end) s]
    explains in each of its stretches *not judged* (not tested, with the lateness, the stretch measured from
    `origin` [s] and what had failed); returns the ids so changed, in the order of the requirements.
    """
    changed = []
    for r in results.ordered():
        stretches = results.stretches.get(r.id, [])
        if r.status != FAIL or not stretches or any(s is None for s in stretches):
            continue
        if r.id not in TIME_TOLERANCE and any(s.tolerance is None for s in stretches):
            continue
        lateness = []
        for s in stretches:
            tolerance = s.tolerance if s.tolerance is not None else TIME_TOLERANCE[r.id][0]
            lateness.append(explained(windows, s, tolerance))
        if not all(lateness):
            continue
        where = '; '.join(f'{s.scenario + " " if s.scenario else ""}{s.t0 - origin:.2f}-{s.t1 - origin:.2f} s into '
                          'the run' for s in stretches)
        why = r.detail or 'failed'
        r.status = NOT_TESTED
        r.detail = not_judged(max(lateness), f'during {where}; on its face: {why}')
        changed.append(r.id)
    return changed
