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

"""The shape of a controller's ramp, judged on the commands it applied (docs/protocol.md, "Ramp shape"): no step
above the travel velocity (or the velocity the ramp inherited, if faster) times one sample period, and no
overshoot past the target beyond the braking distance of the inherited motion plus RAMP_OVERSHOOT.

Used by CTRL-RAMP-1 (ABORT at the commanded velocity) and by the controller's own ramps of CTRL-WD-1 (host
silence), CTRL-LIM-2 and CTRL-LIM-3 (faults), whose travel velocity is OWN_RAMP_VELOCITY.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

LSB = 1e-7                 # [m] displacement resolution of the frames
STEP_TOLERANCE = 0.05      # a step may exceed the velocity bound by 5 % (+ two resolution steps)
RAMP_OVERSHOOT = 1e-6      # [m] passing the target by more than this (beyond the inherited braking) is overshoot
OWN_RAMP_VELOCITY = 0.05   # [m/s] the travel velocity of the controller's own ramps (faults, host silence)


@dataclass(frozen=True)
class RampShape:
    """What a ramp's applied commands show: largest_step [m/s] (one sample's move times the sample rate) against
    step_bound [m/s], overshoot [m] past the target against overshoot_bound [m].
    """

    largest_step: float
    step_bound: float
    overshoot: float
    overshoot_bound: float

    @property
    def ok(self) -> bool:
        return self.largest_step <= self.step_bound and self.overshoot <= self.overshoot_bound

    def describe(self) -> str:
        return (f'largest step {self.largest_step * 1e3:.2f} mm/s (bound {self.step_bound * 1e3:.2f}), overshoot '
                f'past the target {self.overshoot * 1e6:.2f} um (bound {self.overshoot_bound * 1e6:.2f})')

    def why(self) -> str:
        """'' when the shape is right, else what is wrong with it."""
        out = []
        if self.largest_step > self.step_bound:
            out.append(f'a step of {self.largest_step * 1e3:.2f} mm/s, above the velocity bound x one period')
        if self.overshoot > self.overshoot_bound:
            out.append(f'overshoots its target by {self.overshoot * 1e6:.1f} um')
        return '; '.join(out)


def ramp_shape(u, fs: float, target: float, travel_velocity: float, start_velocity: float = 0.0,
               decel: float = math.inf, gaps=None) -> RampShape:
    """The shape of the ramp whose applied commands are u [m] (the command before the ramp first, then one per
    sample), at sample rate fs [Hz], towards target [m].

    travel_velocity [m/s]: the most the ramp may travel at; start_velocity [m/s]: the velocity of the motion it
    inherits (a step of that size is no step); decel [m/s^2]: the braking it may use to stop the inherited motion
    (HostLimits deceleration), whose braking distance v^2 / (2 decel) it may pass the target by, plus
    RAMP_OVERSHOOT. gaps: samples between each two commands of u (len(u) - 1; default 1 each): across samples
    never received (this host's loss) a move is judged per sample, as the most even one the data allow.
    """
    u = [float(x) for x in u]
    gaps = [1] * max(len(u) - 1, 0) if gaps is None else [max(int(n), 1) for n in gaps]
    steps = [abs(b - a) * fs / n for a, b, n in zip(u, u[1:], gaps, strict=False)]
    bound = max(travel_velocity, abs(start_velocity)) * (1 + STEP_TOLERANCE) + 2 * LSB * fs
    direction = math.copysign(1.0, target - u[0]) if u and abs(target - u[0]) > RAMP_OVERSHOOT else 0.0
    # a ramp that starts at its target must not move from it at all
    past = max(((x - target) * direction if direction else abs(x - target) for x in u), default=0.0)
    heading = start_velocity * direction > 0
    braking = start_velocity ** 2 / (2 * decel) if heading and math.isfinite(decel) and decel > 0 else 0.0
    return RampShape(max(steps, default=0.0), bound, max(0.0, past), braking + RAMP_OVERSHOOT)
