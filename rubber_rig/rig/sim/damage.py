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

"""A simulated specimen that fails: fatigue, a sudden crack, a slip in the fixture (SimOptions.damage).

The wrapper counts the load cycles the specimen itself goes through (one per two reversals of the true
displacement of at least REVERSAL [m]), so the damage follows the specimen's history whatever program or
resume drives it, as a real specimen's would. With damage state D (fatigue and crack), crack damping c and
slip s, the force is

    F = (1 - D) * F_intact(x - s) + c * dx/dt

where F_intact is the intact element model (its memory runs on what the specimen really sees, x - s).
"""
import numpy as np

from ..options import DamageSpec

REVERSAL = 10e-6     # [m] a displacement reversal this large counts half a load cycle
MAX_DAMAGE = 0.95    # a specimen keeps 5 % of its stiffness: a torn one still has its fixtures' friction


def sample_at_cycle(x, cycles: float) -> int:
    """Index of the first sample of displacement x [m] at which a specimen counting its reversals as
    DamagedSpecimen does has gone through `cycles` load cycles; -1 if it never does. Replayed on a measured
    displacement it locates a damage onset (transducer noise is far below REVERSAL).
    """
    counter = DamagedSpecimen(None, [], 1.0)
    for i, xi in enumerate(np.asarray(x, dtype=float).tolist()):
        counter._count(xi)
        if counter.cycles >= cycles:
            return i
    return -1


class DamagedSpecimen:
    """Streaming specimen (step(x) -> F, run(x) -> forces, reset()) = `intact` with the `damage` list applied.

    intact: a streaming element model (rubber_rig.models or LinearSpecimen); damage: DamageSpec list; dt [s].
    """

    def __init__(self, intact, damage: list[DamageSpec], dt: float):
        self.intact, self.damage, self.dt = intact, list(damage), float(dt)
        self.reset_counts()

    def reset_counts(self):
        self.half_cycles = 0
        self._extreme = None     # the last extreme of x, and the direction of travel since (+1, -1, 0)
        self._direction = 0
        self._x = None

    def reset(self):
        self.intact.reset()
        self.reset_counts()

    @property
    def cycles(self) -> float:
        """Load cycles so far (half cycles / 2)."""
        return 0.5 * self.half_cycles

    def state(self, n: float) -> tuple[float, float, float]:
        """(D, c [N s/m], s [m]) after n load cycles."""
        d, c, s = 0.0, 0.0, 0.0
        for spec in self.damage:
            if n < spec.cycle:
                continue
            if spec.type == 'fatigue':
                d = 1 - (1 - d) * (1 - spec.loss * ((n - spec.cycle) / spec.life) ** spec.exponent)
            elif spec.type == 'crack':
                d = 1 - (1 - d) * (1 - spec.loss)
                c += spec.damping
            else:
                s += spec.offset
        return min(d, MAX_DAMAGE), c, s

    def _count(self, x: float) -> None:
        """Update the reversal count with the true displacement x [m]."""
        if self._extreme is None:
            self._extreme = x
        elif self._direction == 0:
            if abs(x - self._extreme) > REVERSAL:
                self._extreme, self._direction = x, 1 if x > self._extreme else -1
        elif (x - self._extreme) * self._direction > 0:
            self._extreme = x
        elif (self._extreme - x) * self._direction > REVERSAL:
            self.half_cycles += 1
            self._extreme, self._direction = x, -self._direction

    def step(self, x: float) -> float:
        self._count(x)
        d, c, s = self.state(self.cycles)
        v = 0.0 if self._x is None else (x - self._x) / self.dt
        self._x = x
        return (1 - d) * self.intact.step(x - s) + c * v

    def run(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        states = np.empty((x.size, 3))
        for i, xi in enumerate(x.tolist()):
            self._count(xi)
            states[i] = self.state(self.cycles)
        prev = x[0] if self._x is None else self._x
        v = np.diff(np.concatenate([[prev], x])) / self.dt
        if x.size:
            self._x = float(x[-1])
        force = np.asarray(self.intact.run(x - states[:, 2]), dtype=float)
        return (1 - states[:, 0]) * force + states[:, 1] * v
