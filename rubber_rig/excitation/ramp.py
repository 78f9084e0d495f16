"""The safe ramp: a smooth move from any position and velocity to a rest position, never a step."""
import math

import numpy as np


class SafeRamp:
    """Critically damped second-order follower with velocity and acceleration limits.

    Starts from the current setpoint x0 [m] and velocity v0 [m/s], so there is no step and no velocity jump,
    and settles on `target` [m]. bandwidth [Hz] sets how fast (about 1/bandwidth s per 1e-4 of the distance);
    velocity_max [m/s] and accel_max [m/s^2] bound the motion. Used by the program runner (abort, hold) and by
    the simulated controller (abort, host watchdog).
    """

    def __init__(self, x0: float, v0: float, target: float, sample_rate: float, bandwidth: float = 2.0,
                 velocity_max: float = 0.05, accel_max: float = 20.0, tolerance: float = 5e-8):
        self.x, self.v, self.target = float(x0), float(v0), float(target)
        self.dt = 1.0 / sample_rate
        self.wn = 2 * math.pi * bandwidth
        self.v_max, self.a_max, self.tol = velocity_max, accel_max, tolerance
        self.done = False

    def step(self) -> float:
        """Advance one sample; return the next setpoint [m]."""
        if self.done:
            return self.x
        a = self.wn ** 2 * (self.target - self.x) - 2 * self.wn * self.v
        a = min(max(a, -self.a_max), self.a_max)
        v = self.v + a * self.dt
        if abs(v) > self.v_max:
            # faster than allowed (e.g. aborting a fast sine): brake at accel_max instead of a velocity jump
            v = math.copysign(max(self.v_max, abs(self.v) - self.a_max * self.dt), v)
        self.v = v
        self.x += self.v * self.dt
        if abs(self.x - self.target) < self.tol and abs(self.v) < self.tol * self.wn:
            # the last move is below tol (0.05 um): no perceptible step
            self.x, self.v, self.done = self.target, 0.0, True
        return self.x

    def run(self, n: int) -> np.ndarray:
        """Next n setpoints [m], shape (n,)."""
        return np.array([self.step() for _ in range(n)])
