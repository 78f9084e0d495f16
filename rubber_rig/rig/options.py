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

"""The simulated rig's options (faults, damage, SimOptions) and the typed building of configuration mappings
that RigConfig uses too: every error names its dotted field ("rig config: field 'sim.faults[1].type': ...").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import List

from ..safety import LimitError, Limits
from ..settings import setting
from .can.protocol import PROTOCOL_VERSION
from .conformance.defects import check_defects

FAULT_TYPES = ('drop', 'delay', 'duplicate', 'corrupt', 'stuck_sensor', 'silent_controller', 'bus_flood')
FRAME_NAMES = ('Feedback', 'ControllerStatus', 'Temperature', 'ControllerHeartbeat')


class ConfigError(ValueError):
    """Invalid rig configuration. `field` is the dotted path of the field it concerns ('sim.faults[1].type'),
    which the message names too: "rig config: field 'sim.faults[1].type': unknown fault 'x' (...)".
    """

    def __init__(self, field: str, why: str):
        super().__init__(f"rig config: field '{field}': {why}")
        self.field = field
        self.why = why


@dataclass
class FaultSpec:
    """One injected fault of the simulated rig, active from `start` for `duration` seconds of rig time
    (samples / sample_rate; paced, the time the rig stands idle after its first sample counts too, so a
    window also ends while the rig stands faulted).

    type: drop | delay | duplicate | corrupt (frames named in `frames`, each hit with `probability`),
    stuck_sensor (`sensor` displacement|force freezes), silent_controller (heartbeat and status stop),
    bus_flood (another node on the bus sends 8-byte frames with identifier `frame_id` taking `load` of the bus:
    frames of lower priority are delayed, then lost; only on the timed bus of the paced sim backend).
    delay [s]: how late delayed frames are sent.
    """

    type: str
    start: float = 0.0
    duration: float = math.inf
    probability: float = 1.0
    frames: List[str] = field(default_factory=lambda: ['Feedback'])
    delay: float = 0.05
    sensor: str = 'displacement'
    load: float = 1.0
    frame_id: int = 0x0FF

    def check(self, path):
        if self.type not in FAULT_TYPES:
            raise ConfigError(f'{path}.type', f"unknown fault {self.type!r} "
                              f"(one of: {', '.join(FAULT_TYPES)})")
        if self.start < 0 or self.duration <= 0:
            raise ConfigError(f'{path}.start/duration', "start >= 0 and duration > 0 needed")
        if not 0 <= self.probability <= 1:
            raise ConfigError(f'{path}.probability', "must be within 0..1")
        for i, name in enumerate(self.frames):
            if name not in FRAME_NAMES:
                raise ConfigError(f'{path}.frames[{i}]', f"unknown frame {name!r} "
                                  f"(one of: {', '.join(FRAME_NAMES)})")
        if self.delay <= 0:
            raise ConfigError(f'{path}.delay', "must be > 0")
        if self.sensor not in ('displacement', 'force'):
            raise ConfigError(f'{path}.sensor', "displacement or force")
        if not 0 < self.load <= 1:
            raise ConfigError(f'{path}.load', "bus share within (0, 1]")
        if not 0 <= self.frame_id <= 0x7FF:
            raise ConfigError(f'{path}.frame_id', "an 11-bit identifier 0..0x7FF")

    def active(self, t: float) -> bool:
        """True while the fault is active at rig time t [s]."""
        return self.start <= t < self.start + self.duration


DAMAGE_TYPES = ('fatigue', 'crack', 'slip')


@dataclass
class DamageSpec:
    """A way the simulated specimen fails, from load cycle `cycle` on (cycles counted by the specimen itself:
    one per two displacement reversals of at least 10 um, from the simulator's start).

    fatigue: gradual stiffness loss, D(n) = loss * ((n - cycle) / life) ** exponent (a Woehler-like power law:
             exponent 1 loses stiffness at a constant rate per cycle, larger exponents accelerate towards the
             end of life as elastomer specimens do); the force is (1 - D) x the intact specimen's, D <= 0.95.
    crack:   a sudden partial crack: the force drops to (1 - loss) x the intact one and the crack faces add a
             viscous damping `damping` [N s/m].
    slip:    the specimen slips in its fixture by `offset` [m]: it sees the actuator displacement minus the
             offset while the displacement transducer (on the actuator) does not see it.
    """

    type: str
    cycle: float = 0.0
    loss: float = 0.3
    life: float = 1000.0
    exponent: float = 1.0
    damping: float = 0.0
    offset: float = 0.0

    def check(self, path):
        if self.type not in DAMAGE_TYPES:
            raise ConfigError(f'{path}.type', f"unknown damage {self.type!r} (one of: {', '.join(DAMAGE_TYPES)})")
        for name in ('cycle', 'loss', 'life', 'exponent', 'damping', 'offset'):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(f'{path}.{name}', 'must be finite')
        if self.cycle < 0:
            raise ConfigError(f'{path}.cycle', 'must be >= 0')
        if not 0 <= self.loss <= 0.95:
            raise ConfigError(f'{path}.loss', f'{self.loss!r} outside 0..0.95 (a fraction of the stiffness)')
        if self.life <= 0 or self.exponent <= 0:
            raise ConfigError(f'{path}.life/exponent', 'must be > 0')
        if self.damping < 0:
            raise ConfigError(f'{path}.damping', 'must be >= 0 N s/m')
        if abs(self.offset) > 0.01:
            raise ConfigError(f'{path}.offset', f'{self.offset!r} m: a slip of at most 10 mm')


@dataclass
class SimOptions:
    """Simulated servo-hydraulic rig. SI units.

    specimen: spec for rubber_rig.models.build_model (default seed-000 at 20 degC; parameter_set, model_file), or
    {"model": "linear", "stiffness": N/m, "damping": N s/m}. The actuator is a second-order position loop
    (natural frequency [Hz], damping ratio) with a velocity limit [m/s]. Sensors: noise (std), offset,
    resolution; temperature [degC]. The load cell reports force_gain x the true force of force_delay [s]
    earlier (a delay line, linear interpolation between samples) + force_offset + force_drift x t + noise, quantised.
    host_timeout [s]: host heartbeat silence after which the controller ramps to rest on its own.
    """

    specimen: dict = field(default_factory=lambda: {'model': 'fractional_zener_berg', 'temperature': 20.0})
    actuator_frequency: float = setting(80.0, 'natural frequency of the actuator position loop', units='Hz',
                                        range=(1.0, 2000.0))
    actuator_damping: float = setting(0.8, 'damping ratio of the actuator position loop', units='-',
                                      range=(0.05, 5.0))
    actuator_velocity_max: float = setting(0.5, 'velocity limit of the actuator', units='m/s', range=(1e-4, 10.0))
    displacement_noise: float = setting(0.2e-6, 'displacement transducer noise, standard deviation', units='m',
                                        range=(0.0, 1e-3))
    displacement_offset: float = setting(0.0, 'displacement transducer offset', units='m', range=(-1e-2, 1e-2))
    displacement_resolution: float = setting(1e-7, 'displacement transducer resolution', units='m',
                                             range=(1e-12, 1e-3))
    force_noise: float = setting(2.0, 'load cell noise, standard deviation', units='N', range=(0.0, 1e4))
    force_offset: float = setting(0.0, 'load cell offset', units='N', range=(-1e5, 1e5))
    force_drift: float = setting(0.0, 'load cell zero drift: the offset grows by this much per second of the run',
                                 units='N/s', range=(-1e3, 1e3))
    force_resolution: float = setting(0.01, 'load cell resolution', units='N', range=(1e-9, 100.0))
    force_delay: float = setting(0.0, 'load cell delay: it reports the true force of this long ago (linear '
                                 'interpolation between samples)', units='s', range=(0.0, 0.1))
    force_gain: float = setting(1.0, 'load cell gain: it reports gain x the true force (+ offset + noise)',
                                units='-', range=(0.01, 100.0))
    temperature: float = setting(20.0, 'specimen temperature reported on the temperature channel', units='degC',
                                 range=(-60.0, 150.0))
    temperature_noise: float = setting(0.02, 'temperature channel noise', units='K', range=(0.0, 10.0))
    host_timeout: float = setting(0.5, 'host heartbeat silence after which the controller ramps to rest',
                                  units='s', range=(0.01, 60.0))
    seed: int = setting(0, 'random seed of the simulated sensors', range=(0, 2**31 - 1))
    protocol_version: int = setting(PROTOCOL_VERSION, 'protocol version the simulated controller states in '
                                    'ControllerIdentity (another value stands for a controller of another version)',
                                    range=(0, 255))
    defects: List[str] = setting(doc='deliberate protocol defects of the simulated controller, each breaking one '
                                 'requirement of docs/protocol.md (conformance testing only; YAML list, e.g. '
                                 '[heartbeat_80ms])', yaml_text=True, default_factory=list)
    faults: List[FaultSpec] = setting(
        doc='injected faults of the simulated rig (YAML list, e.g. [{type: silent_controller, start: 2.0}]; types: '
            + ', '.join(FAULT_TYPES) + ')', yaml_text=True, default_factory=list)
    damage: List[DamageSpec] = setting(
        doc='ways the simulated specimen fails (YAML list, e.g. [{type: crack, cycle: 200, loss: 0.3}]; types: '
            + ', '.join(DAMAGE_TYPES) + '; see DamageSpec)', yaml_text=True, default_factory=list)

    def check(self, path='sim'):
        if not isinstance(self.specimen, dict):
            raise ConfigError(f'{path}.specimen', "expected a mapping like "
                              "{model: fractional_zener_berg, temperature: 20.0}")
        positive = ('actuator_frequency', 'actuator_damping', 'actuator_velocity_max', 'displacement_resolution',
                    'force_resolution', 'host_timeout')
        for name in positive:
            if getattr(self, name) <= 0:
                raise ConfigError(f'{path}.{name}', "must be > 0")
        for name in ('displacement_noise', 'force_noise', 'temperature_noise'):
            if getattr(self, name) < 0:
                raise ConfigError(f'{path}.{name}', "must be >= 0")
        if not 0 <= self.force_delay <= 0.1:
            raise ConfigError(f'{path}.force_delay', f"{self.force_delay!r} s outside 0..0.1")
        if not (math.isfinite(self.force_gain) and self.force_gain > 0):
            raise ConfigError(f'{path}.force_gain', f"must be > 0, got {self.force_gain!r}")
        for i, f in enumerate(self.faults):
            f.check(f'{path}.faults[{i}]')
        for i, d in enumerate(self.damage):
            d.check(f'{path}.damage[{i}]')
        why = check_defects(self.defects)
        if why:
            raise ConfigError(f'{path}.defects', why)
        if not 0 <= self.protocol_version <= 255:
            raise ConfigError(f'{path}.protocol_version', 'within 0..255')


def _build(cls, data, path):
    """Dataclass `cls` from mapping `data`, type-checked field by field (errors name the dotted path)."""
    where = path or 'rig config'
    if not isinstance(data, dict):
        raise ConfigError(where, f"expected a mapping, got {type(data).__name__}")
    known = {f.name: f for f in fields(cls)}
    kwargs = {}
    for key, value in data.items():
        fpath = f'{path}.{key}' if path else key
        if key not in known:
            raise ConfigError(fpath, f"unknown (known: {', '.join(sorted(known))})")
        kwargs[key] = _convert(known[key].type, value, fpath)
    return cls(**kwargs)


def _convert(typ, value, fpath):
    typ = typ if isinstance(typ, str) else getattr(typ, '__name__', str(typ))
    bad = ConfigError(fpath, f"expected {typ}, got {value!r}")
    if typ == 'Limits':
        try:
            return Limits.from_dict(value)
        except LimitError as exc:
            raise ConfigError(f'{fpath}.{exc.field}' if exc.field else fpath, str(exc)) from None
    if typ == 'SimOptions':
        return _build(SimOptions, value, fpath)
    if typ == 'List[FaultSpec]':
        if not isinstance(value, list):
            raise bad
        return [_build(FaultSpec, v, f'{fpath}[{i}]') for i, v in enumerate(value)]
    if typ == 'List[DamageSpec]':
        if not isinstance(value, list):
            raise bad
        return [_build(DamageSpec, v, f'{fpath}[{i}]') for i, v in enumerate(value)]
    if typ == 'float':
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad
        return float(value)
    if typ == 'int':
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad
        return value
    if typ == 'bool':
        if not isinstance(value, bool):
            raise bad
        return value
    if typ == 'str':
        if not isinstance(value, str):
            raise bad
        return value
    if typ == 'Optional[str]':
        if value is not None and not isinstance(value, (str, int)):
            raise bad
        return value
    if typ == 'dict':
        if not isinstance(value, dict):
            raise bad
        return dict(value)
    if typ == 'List[str]':
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise bad
        return list(value)
    return value
