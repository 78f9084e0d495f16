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

"""The conformance scenario of HostLimits that tighten while setpoints are queued (CTRL-LIM-2, docs/protocol.md
"Tighter limits with setpoints queued"): new limits bind every setpoint not yet applied, so a controller that has
a queued setpoint outside them must refuse it when the limits arrive, as if it had just arrived (flush, fault
displacement_limit, ramp to rest inside the new limits), not when its tick comes and never by applying it.
"""
from __future__ import annotations

from ..can.protocol import FAULT_DISPLACEMENT_LIMIT, fault_names
from .active_faults import _fault_bits_since, _judge_fault_bits, _own_ramp_shape
from .host_timing import explains, not_judged
from .link import LEAD, LSB, RAMP_VELOCITY, REST_TIMEOUT, judges
from .report import FAIL, NOT_TESTED, PASS

#: [s] of controller time (sample sequences) from the last sample this host had seen when it sent the tighter
#: HostLimits to the sample of the status that first reports the refusal: the frame's way over the bus, one
#: ControllerStatus period (10 ms) and the feedback's own delay (CTRL-FB-2) fit with room; a controller that waits
#: for the tick of the first setpoint outside the limits takes LEAD x 0.36 (about 0.1 s) here
REFUSE_TIME = 0.05
START_FRACTION = 0.2     # the tighter limits are sent once the command has moved this share of the way to the edge
LIMIT_FRACTION = 0.6     # ... at this share of the way from the command to the last setpoint queued


@judges('CTRL-LIM-2', 'CTRL-FAULT-1')
def s_tightened_limits(link):
    """HostLimits that tighten while setpoints outside them are queued, upwards and downwards (CTRL-LIM-2,
    CTRL-FAULT-1).
    """
    for side in (+1, -1):
        _tighten_under_queue(link, side)


def _tighten_under_queue(link, side: int):
    """Stream a RAMP_VELOCITY move towards 0.8 x the envelope on `side` (+1 up, -1 down) inside the whole
    envelope; once the command is START_FRACTION of the way, stop sending and send HostLimits whose bound on that
    side lies between the command and the last setpoint queued (LEAD ahead). The controller must fault
    displacement_limit within REFUSE_TIME, never apply a setpoint beyond the new bound, and ramp to rest inside it.
    """
    env = link.env
    edge = env.upper if side > 0 else env.lower
    link.limits(env.lower, env.upper)
    p0, target = link.position, 0.8 * edge
    first = link.next_sequence() + 1000
    wave = link.ramp_to(p0, target, RAMP_VELOCITY)
    mark = p0 + START_FRACTION * (target - p0)
    t = link.now()
    try:
        sent = link.stream(first, wave, abs(target - p0) / RAMP_VELOCITY + LEAD,
                           until=lambda: (link.position - mark) * side >= 0 or link.state not in ('idle', 'running'))
        with link.lock:
            seen = link.samples[-1].seq if link.samples else first
        u_now, queued_end = link.position, wave(sent - 1 - first)
        bound = u_now + LIMIT_FRACTION * (queued_end - u_now)
        if link.state != 'running' or (queued_end - u_now) * side < 20 * LSB:
            link.results.put('CTRL-LIM-2', FAIL, f'tighter limits: state {link.state} at '
                             f'{u_now * 1e3:.4f} mm before any limits were changed',
                             'a stream inside the limits must run')
            return
        t_limits = link.now()
        link.limits(*((env.lower, bound) if side > 0 else (bound, env.upper)))
    finally:
        link.heartbeat = True
    link._wait(lambda: link.state in ('idle', 'fault'), REST_TIMEOUT)
    link._sleep(0.05)
    _judge_refusal(link, side, bound, u_now, queued_end, seen, t_limits)
    _judge_fault_bits(link, 'tighter limits with setpoints queued outside them', _fault_bits_since(link, t),
                      FAULT_DISPLACEMENT_LIMIT, t)
    link.limits(env.lower, env.upper)
    link.to_rest(link.position)


def _judge_refusal(link, side: int, bound: float, u_now: float, queued_end: float, seen: int, t_limits: float):
    """CTRL-LIM-2 of the tightened limits: nothing applied beyond `bound`, a displacement_limit fault reported
    within REFUSE_TIME of controller time after sample `seen` (the last one this host had when it sent them), and
    a fault ramp of the controller's own shape.
    """
    samples = link._samples_since(t_limits)
    u = [s.u for s in samples]
    far = max((x * side for x in u), default=u_now * side) * side
    refused = next((s for s in link._states_since(t_limits) if s[1] not in ('running', 'holding')), None)
    after = (refused[3] - seen) / link.fs if refused else float('inf')
    faults = _fault_bits_since(link, t_limits)
    shape = _own_ramp_shape(link, samples, 0.0)
    name = 'HL_DisplacementMax' if side > 0 else 'HL_DisplacementMin'
    measured = (f'{name} tightened to {bound * 1e3:.4f} mm with the command at {u_now * 1e3:.4f} mm and setpoints '
                f'queued to {queued_end * 1e3:.4f} mm: refused {after * 1e3:.0f} ms after, farthest applied '
                f'{far * 1e3:.4f} mm, faults {fault_names(faults)}, state {link.state}; fault ramp: '
                f'{shape.describe()}')
    inside = far * side <= bound * side + 1.5 * LSB
    ok = inside and after <= REFUSE_TIME and faults == FAULT_DISPLACEMENT_LIMIT and link.state == 'fault' and shape.ok
    if not ok and inside and faults and after > REFUSE_TIME and refused is not None:
        late = explains(link.trace.host_late, t_limits, refused[0], after - REFUSE_TIME)
        if late:
            link.results.put('CTRL-LIM-2', NOT_TESTED, measured, not_judged(late, 'the refusal of tighter limits'))
            return
    why = (f'a queued setpoint beyond the new {name} must never be applied' if not inside else
           f'tighter limits must refuse the queued setpoints outside them when they arrive (within '
           f'{REFUSE_TIME * 1e3:.0f} ms), not when their tick comes' if after > REFUSE_TIME else
           shape.why() or 'the refusal must fault displacement_limit and ramp to rest')
    link.results.put('CTRL-LIM-2', PASS if ok else FAIL, measured, '' if ok else why)
