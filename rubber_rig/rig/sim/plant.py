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

"""Physics of the simulated rig: servo-hydraulic actuator position loop and sensors."""
import math

import numpy as np
from scipy.linalg import expm


class Actuator:
    """Second-order position loop x'' = wn^2 (u - x) - 2 zeta wn x' with a velocity limit, discretised exactly
    (zero-order hold) at the sample period. frequency [Hz], velocity_max [m/s]; u and x in m.

    Finite bandwidth makes amplitude and phase errors appear at high frequency as on a real rig.
    """

    def __init__(self, frequency: float, damping: float, velocity_max: float, sample_rate: float,
                 x0: float = 0.0):
        wn = 2 * math.pi * frequency
        a = np.array([[0.0, 1.0, 0.0], [-wn * wn, -2 * damping * wn, wn * wn], [0.0, 0.0, 0.0]])
        phi = expm(a / sample_rate)
        (self.a11, self.a12, self.b1), (self.a21, self.a22, self.b2) = phi[0], phi[1]
        self.v_max = velocity_max
        self.x, self.v = float(x0), 0.0

    def step(self, u: float) -> float:
        """Apply command u [m] for one sample; return the actuator position [m]."""
        x = self.a11 * self.x + self.a12 * self.v + self.b1 * u
        v = self.a21 * self.x + self.a22 * self.v + self.b2 * u
        if v > self.v_max:
            v = self.v_max
        elif v < -self.v_max:
            v = -self.v_max
        self.x, self.v = x, v
        return x

    def run(self, u) -> tuple[list, list]:
        """Apply commands u [m] (a list), one per sample; return the positions [m] and velocities [m/s] (lists),
        exactly as repeated step() calls.
        """
        a11, a12, b1, a21, a22, b2, vmax = self.a11, self.a12, self.b1, self.a21, self.a22, self.b2, self.v_max
        x0, v0 = self.x, self.v
        xs, vs = [], []
        for c in u:
            x = a11 * x0 + a12 * v0 + b1 * c
            v = a21 * x0 + a22 * v0 + b2 * c
            if v > vmax:
                v = vmax
            elif v < -vmax:
                v = -vmax
            xs.append(x)
            vs.append(v)
            x0, v0 = x, v
        self.x, self.v = x0, v0
        return xs, vs


class DelayLine:
    """A transducer's delay of `delay` samples (>= 0, fractional: linear interpolation between the two samples
    around it): step(v) and run(values) return the input of `delay` samples ago, run() exactly as repeated
    step() calls. Before the first input the line holds that first input (the rig stood still).
    """

    def __init__(self, delay: float):
        if not (math.isfinite(delay) and delay >= 0):
            raise ValueError(f'delay must be a finite number of samples >= 0, got {delay!r}')
        self.whole = int(math.floor(delay))
        self.frac = float(delay - self.whole)
        self.size = self.whole + 2                # inputs kept: the newest and the two around the delay
        self._hist = None                         # the last `size` inputs, oldest first

    def _start(self, first: float):
        if self._hist is None:
            self._hist = [float(first)] * self.size

    def step(self, value: float) -> float:
        self._start(value)
        hist = self._hist
        hist.append(float(value))
        del hist[0]
        a, b = hist[-1 - self.whole], hist[-2 - self.whole]
        return a if self.frac == 0.0 else (1.0 - self.frac) * a + self.frac * b

    def run(self, values) -> np.ndarray:
        values = np.asarray(values, dtype=float)
        if values.size == 0:
            return values.copy()
        self._start(values[0])
        line = np.concatenate([np.asarray(self._hist, dtype=float), values])
        end = line.size
        a = line[self.size - self.whole:end - self.whole]
        b = line[self.size - self.whole - 1:end - self.whole - 1]
        self._hist = line[-self.size:].tolist()
        if self.frac == 0.0:
            return a.copy()
        with np.errstate(invalid='ignore', over='ignore'):
            return (1.0 - self.frac) * a + self.frac * b


class Sensor:
    """Transducer with gain, Gaussian noise (std), offset, zero drift (per reading) and resolution (quantisation
    step), all in its unit: reads gain x true + offset + drift x readings so far + noise, quantised. Noise is
    drawn in blocks from a seeded generator so runs are reproducible.
    """

    SCALAR_UP_TO = 8       # read_many reads this many values or fewer one by one (the same numbers, faster)

    def __init__(self, noise: float, offset: float, resolution: float, rng: np.random.Generator, block=4096,
                 gain: float = 1.0, drift: float = 0.0):
        self.noise, self.offset, self.res, self.gain = noise, offset, resolution, gain
        self.drift, self._reads = drift, 0     # zero drift per reading (a load cell warming up)
        self._rng, self._block = rng, block
        self._buf, self._i = np.empty(0), 0
        self.stuck_value = None

    def read(self, true_value: float) -> float:
        """Measured value for the true value (or the frozen value while stuck).

        A true value that is not finite (a diverged specimen model), or one beyond what the quantiser can count,
        reads NaN: an invalid channel, for the controller to fault on, rather than an exception in its loop. The
        noise sequence advances as for any other sample.
        """
        if self.stuck_value is not None:
            return self.stuck_value
        if self._i >= self._buf.size:
            self._buf, self._i = self._rng.standard_normal(self._block) * self.noise, 0
        n = float(self._buf[self._i])   # Python floats: an overflow is inf, without a numpy warning
        self._i += 1
        offset = self.offset + self.drift * self._reads
        self._reads += 1
        counts = (self.gain * true_value + offset + n) / self.res
        if not math.isfinite(counts):
            return math.nan
        return round(counts) * self.res

    def read_frame(self, true_values) -> list:
        """read_many() as a frame carries the readings (a list of floats): one that is not finite (an invalid
        channel) is sent as 0, and the status frame carries the sensor fault.
        """
        if len(true_values) <= self.SCALAR_UP_TO:
            readings = [self.read(float(v)) for v in true_values]
            return [r if math.isfinite(r) else 0.0 for r in readings]
        readings = self.read_many(true_values)
        return np.where(np.isfinite(readings), readings, 0.0).tolist()

    def read_many(self, true_values) -> np.ndarray:
        """Measured values for an array of true values: the same numbers and noise sequence as read() one by one
        (not while stuck: the caller reads stuck sensors one by one).
        """
        if len(true_values) <= self.SCALAR_UP_TO:    # a paced rig's few samples per wake-up: numpy costs more
            return np.array([self.read(float(v)) for v in true_values])
        true_values = np.asarray(true_values, dtype=float)
        n = true_values.size
        noise = np.empty(n)
        done = 0
        while done < n:
            if self._i >= self._buf.size:
                self._buf, self._i = self._rng.standard_normal(self._block) * self.noise, 0
            take = min(n - done, self._buf.size - self._i)
            noise[done:done + take] = self._buf[self._i:self._i + take]
            self._i += take
            done += take
        offset = self.offset + self.drift * (self._reads + np.arange(n)) if self.drift else self.offset
        self._reads += n
        with np.errstate(over='ignore', invalid='ignore'):
            counts = (self.gain * true_values + offset + noise) / self.res
            out = np.round(counts) * self.res
        out[~np.isfinite(counts)] = np.nan
        return out


def first_invalid(values) -> int:
    """Index of the first value that is not finite (a list of a few floats, or an array), -1 if all are."""
    if isinstance(values, list):
        return next((i for i, v in enumerate(values) if not math.isfinite(v)), -1)
    finite = np.isfinite(values)
    return -1 if finite.all() else int(np.argmin(finite))
