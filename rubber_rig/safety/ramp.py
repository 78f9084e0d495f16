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

"""The safe ramp: a smooth move from any position and velocity to a rest position, never a step, never
outside the displacement limits, never faster than the stated velocity and deceleration.

Why a velocity-from-distance law and not a linear follower: a follower (second-order loop towards the
target) overshoots when it starts fast (aborting a 14 Hz sine near its peak) and has no notion of the limits;
the braking curve below is the discrete-time stopping distance, so the ramp provably stops inside
[lower, upper] whenever the starting state can stop there at ``decel_max`` (which is what
``stopping_positions`` lets the host check on every streamed setpoint before it is sent).
"""
import math

import numpy as np

# Defaults of the controller-side and host-side ramps [m/s, m/s^2]
RAMP_VELOCITY = 0.05       # travel speed towards the rest position
RAMP_ACCEL = 0.2           # gentle acceleration/deceleration of the travel part (1 mm in 0.14 s)
BRAKE_DECEL = 20.0         # braking of the motion a ramp inherits (a fast sine at abort)
DECEL_MAX = 100.0          # hardest braking, only where the displacement limits need it (Limits.deceleration_max)


def braking_velocity(distance, dv: float, dt: float):
    """Largest speed [m/s] from which a motion that loses at most dv [m/s] per sample of dt [s] still stops
    within `distance` [m] (>= 0): the positive root of dt * v * (v / dv + 1) / 2 = distance, the distance
    covered by v, v - dv, v - 2 dv, ... Works on scalars and arrays.
    """
    d = np.maximum(distance, 0.0)
    return 0.5 * (-dv + np.sqrt(dv * dv + 8.0 * dv * d / dt))


def stopping_positions(x, v, decel: float, sample_rate: float):
    """Where a motion that reached positions x [m] with velocities v [m/s] (the last step's; arrays of the same
    shape) comes to rest when it brakes at `decel` [m/s^2] from the next step on: the steps v - dv, v - 2 dv,
    ... (dv = decel / sample_rate) cover dt * |v| * (|v| / dv - 1) / 2 - the distance SafeRamp needs.
    """
    dt = 1.0 / sample_rate
    v = np.asarray(v, dtype=float)
    speed = np.abs(v)
    return np.asarray(x, dtype=float) + np.sign(v) * dt * speed * np.maximum(speed / (decel * dt) - 1.0, 0.0) / 2.0


class SafeRamp:
    """Move from x0 [m] at velocity v0 [m/s] to `target` [m] and stop there.

    The motion the ramp inherits is braked at the deceleration that stops it at the target if it is heading
    there (at most ``brake_decel``), else at ``brake_decel``; the travel to the target then has a trapezoidal
    profile (``velocity_max``, ``accel_max``). With `lower`/`upper` [m] the motion never plans past a bound it
    could not stop before at ``decel_max`` (harder braking than brake_decel, only where the limits need it); if
    even that cannot keep it inside (a start state the host did not check), it brakes harder still and counts
    the samples in ``decel_exceeded`` rather than leave the limits. Position and velocity are continuous at the
    start (no step); the last move is below ``tolerance`` (0.05 um). Used by the program runner (abort, hold,
    approach) and the simulated controller (abort, hold, host watchdog).
    """

    def __init__(self, x0: float, v0: float, target: float, sample_rate: float, *,
                 velocity_max: float = RAMP_VELOCITY, accel_max: float = RAMP_ACCEL, brake_decel: float = BRAKE_DECEL,
                 decel_max: float = DECEL_MAX, lower: float = -math.inf, upper: float = math.inf,
                 tolerance: float = 5e-8):
        if not lower < upper:
            raise ValueError(f'SafeRamp: lower {lower} must be below upper {upper}')
        self.x, self.v = float(x0), float(v0)
        self.target = min(max(float(target), float(lower)), float(upper))
        self.lower, self.upper = float(lower), float(upper)
        if not self.lower <= self.x <= self.upper:
            # a start outside the bounds (limits tightened under a running rig) is never clamped with a step:
            # the violated bound widens to where the motion can stop at decel_max; the ramp comes back inside
            stop = float(stopping_positions(self.x, self.v, max(float(decel_max), float(accel_max)), sample_rate))
            self.lower, self.upper = min(self.lower, self.x, stop), max(self.upper, self.x, stop)
        self.dt = 1.0 / float(sample_rate)
        self.v_max, self.tol = float(velocity_max), float(tolerance)
        self.dv_travel = float(accel_max) * self.dt
        self.dv_limit = max(float(decel_max), float(accel_max)) * self.dt
        accel_max = float(accel_max)
        self.dv_brake = min(max(float(brake_decel), accel_max), max(float(decel_max), accel_max)) * self.dt
        self.decel_exceeded = 0      # samples where staying inside [lower, upper] needed more than decel_max
        self.done = False

    def step(self) -> float:
        """Advance one sample; return the next setpoint [m]."""
        if self.done:
            return self.x
        dt, v, x = self.dt, self.v, self.x
        dist = self.target - x
        d = abs(dist)
        travel = math.copysign(min(self.v_max, float(braking_velocity(d, self.dv_travel, dt)), d / dt), dist) \
            if dist else 0.0
        if v and (v > 0) == (dist > 0) and abs(v) > abs(travel) + self.dv_travel:
            # heading for the target too fast for the gentle profile: brake so as to stop at the target
            need = v * v * dt / (2 * d - abs(v) * dt) if 2 * d > abs(v) * dt else math.inf
            v_new = v - math.copysign(min(max(need, self.dv_travel), self.dv_brake, abs(v)), v)
        elif v and (v > 0) != (dist > 0) and abs(v) > self.dv_travel:
            v_new = v - math.copysign(min(self.dv_brake, abs(v)), v)   # heading away: brake, then travel back
        else:
            v_new = v + max(-self.dv_travel, min(self.dv_travel, travel - v))
        # never plan past a bound the motion could not stop before at decel_max
        room = (self.upper - x) if v_new > 0 else (x - self.lower)
        v_room = float(braking_velocity(room, self.dv_limit, dt))
        if abs(v_new) > v_room:
            if abs(v) - v_room > self.dv_limit * (1 + 1e-9):
                self.decel_exceeded += 1
            v_new = math.copysign(v_room, v_new)
        x_new = min(max(x + v_new * dt, self.lower), self.upper)
        self.v, self.x = (x_new - x) / dt, x_new
        if abs(self.target - self.x) <= max(self.tol, 1e-12) and abs(self.v) <= self.dv_travel:
            self.x, self.v, self.done = self.target, 0.0, True
        return self.x

    def run(self, n: int) -> np.ndarray:
        """Next n setpoints [m], shape (n,)."""
        return np.array([self.step() for _ in range(n)])
