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

"""The power-up scenario (CTRL-PWR-1): what the controller does when it is switched on while the run listens,
and that it takes no setpoint before a HostStreamStart (a scenario of active.SCENARIOS: a function of the run's
link).
"""
from __future__ import annotations

from ..can.protocol import PROTOCOL_VERSION, STATES
from .link import Aborted, judges
from .report import FAIL, PASS


@judges('CTRL-PWR-1')
def s_power_up(link):
    """Power-up (CTRL-PWR-1)."""
    link.power_up()
    if not link._wait(lambda: any(f.host is False for f in link.trace.frames), 60.0):
        raise Aborted('the controller sent nothing within 60 s of power-up')
    with link.lock:
        t0 = next(f.t for f in link.trace.frames if f.host is False)
    link._sleep(1.5)
    with link.lock:
        first = [f for f in link.trace.frames if f.host is False and f.t <= t0 + 1.0 and not f.malformed]
    ident = [f for f in first if f.name == 'ControllerIdentity']
    states = {STATES[int(f.signals['ST_State'])] if int(f.signals['ST_State']) < len(STATES) else '?'
              for f in first if f.name == 'ControllerStatus'}
    faults = [f for f in first if f.name == 'ControllerStatus' and int(f.signals['ST_Faults'])]
    ticking = [f for f in first if f.samples is not None]
    taken, probe_states = _unannounced_setpoints(link)
    ok = (bool(ident) and int(ident[0].signals['CI_Protocol']) == PROTOCOL_VERSION and bool(states)
          and states <= {'idle', 'unconfigured'} and not faults and not ticking)
    link.results.put('CTRL-PWR-1', PASS if ok and not taken else FAIL,
                     f'first second after power-up: {len(ident)} ControllerIdentity, states {sorted(states)}, '
                     f'{len(faults)} status frames with faults, {len(ticking)} feedback frames; setpoints '
                     f'without HostStreamStart: {taken} samples taken, states {sorted(probe_states)}',
                     '' if ok and not taken else 'at power-up the controller must identify itself, idle, at rest, '
                     'unfaulted, and take no setpoint before a HostStreamStart')


def _unannounced_setpoints(link) -> tuple[int, set]:
    """CTRL-PWR-1: setpoints at the rest position 0 m (HostLimits the envelope, heartbeat on) for sequences
    from 0, with no HostStreamStart since power-up: (samples the controller took, states it reported) within
    0.3 s. A controller that takes them is brought back to rest.
    """
    link.limits(link.env.lower, link.env.upper)
    link.heartbeat = True
    t = link.now()
    per = link.frames.setpoints_per_frame
    for k in range(0, 10 * per, per):
        link.send_setpoints(k, [0.0] * per, record=False)
    link._sleep(0.3)
    taken = len(link._samples_since(t))
    states = {s[1] for s in link._states_since(t)}
    if taken or link.state in ('running', 'holding', 'ramping_down'):
        link.to_rest(0.0)
    link.heartbeat = False
    return taken, states
