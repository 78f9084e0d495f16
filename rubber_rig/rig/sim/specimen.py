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

"""The specimen of the simulated rig: an element model from rubber_rig.models (default seed 000 at 20 degC),
or a plain linear spring + dashpot for quick checks.

Every element model is built the one way the element_model node builds its model too: through its ModelSpec and
the element catalogue (rubber_rig.models.catalogue), so any model file runs both as the simulated specimen and
online, and a parameter set or a temperature of seed 000 is the model file it describes.
"""
from rubber_rig.models import build_model

from ..config import ConfigError
from .damage import DamagedSpecimen


class LinearSpecimen:
    """Kelvin-Voigt element F = k x + c dx/dt (stiffness [N/m], damping [N s/m]) at time step dt [s].
    Same streaming interface as the element models: step(x) -> F, run(x_array) -> forces, reset().
    """

    def __init__(self, stiffness: float, damping: float, dt: float):
        self.k, self.c, self.dt = float(stiffness), float(damping), float(dt)
        self._x = None

    def step(self, x: float) -> float:
        v = 0.0 if self._x is None else (x - self._x) / self.dt
        self._x = x
        return self.k * x + self.c * v

    def run(self, x):
        return [self.step(float(v)) for v in x]

    def reset(self):
        self._x = None


def build_specimen(spec: dict, dt: float, damage: list = ()):
    """Streaming specimen model for `spec` at time step dt [s], failing as `damage` (DamageSpec list) says.

    {"model": "linear", "stiffness": N/m, "damping": N s/m} builds LinearSpecimen; anything else goes to
    rubber_rig.models.build_model: {"model": "fractional_zener_berg", "temperature": 20.0}, {"parameter_set":
    "swing_arm_joint_20C"} (a model file there too, as the rig driver's sim.specimen.parameter_set passes it),
    {"model_file": "specimen.yaml"} or a model file's mapping {"elements": [...]}, each with an optional
    "friction_reversal_threshold" [m] and fractional "scheme".
    """
    spec = dict(spec)
    if spec.get('model') == 'linear':
        unknown = set(spec) - {'model', 'stiffness', 'damping'}
        if unknown:
            raise ConfigError(f'sim.specimen.{sorted(unknown)[0]}', "unknown for the linear "
                              "specimen (stiffness, damping)")
        intact = LinearSpecimen(spec.get('stiffness', 1.3e7), spec.get('damping', 2.0e4), dt)
    else:
        try:
            intact = build_model(spec, dt)
        except (KeyError, ValueError) as exc:
            raise ConfigError('sim.specimen', str(exc)) from None
    return DamagedSpecimen(intact, damage, dt) if damage else intact
