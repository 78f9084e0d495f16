"""Rig configuration: which bus, which rate, which limits, and the simulated rig's options.

`RigConfig.from_dict` validates everything before anything is opened or sent; errors name the field
(e.g. "rig config: field 'sim.faults[1].type': ...")."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import List, Optional

from ..excitation.limits import LimitError, Limits


class ConfigError(ValueError):
    """Invalid rig configuration; the message names the field."""


FAULT_TYPES = ('drop', 'delay', 'duplicate', 'corrupt', 'stuck_sensor', 'silent_controller')
FRAME_NAMES = ('Feedback', 'ControllerStatus', 'Temperature', 'ControllerHeartbeat')


@dataclass
class FaultSpec:
    """One injected fault of the simulated rig, active from `start` for `duration` seconds of rig time
    (samples / sample_rate; paced, the time the rig stands idle after its first sample counts too, so a
    window also ends while the rig stands faulted).

    type: drop | delay | duplicate | corrupt (frames named in `frames`, each hit with `probability`),
    stuck_sensor (`sensor` displacement|force freezes), silent_controller (heartbeat and status stop).
    delay [s]: how late delayed frames are sent."""
    type: str
    start: float = 0.0
    duration: float = math.inf
    probability: float = 1.0
    frames: List[str] = field(default_factory=lambda: ['Feedback'])
    delay: float = 0.05
    sensor: str = 'displacement'

    def check(self, path):
        if self.type not in FAULT_TYPES:
            raise ConfigError(f"rig config: field '{path}.type': unknown fault {self.type!r} "
                              f"(one of: {', '.join(FAULT_TYPES)})")
        if self.start < 0 or self.duration <= 0:
            raise ConfigError(f"rig config: field '{path}.start/duration': start >= 0 and duration > 0 needed")
        if not 0 <= self.probability <= 1:
            raise ConfigError(f"rig config: field '{path}.probability': must be within 0..1")
        for i, name in enumerate(self.frames):
            if name not in FRAME_NAMES:
                raise ConfigError(f"rig config: field '{path}.frames[{i}]': unknown frame {name!r} "
                                  f"(one of: {', '.join(FRAME_NAMES)})")
        if self.delay <= 0:
            raise ConfigError(f"rig config: field '{path}.delay': must be > 0")
        if self.sensor not in ('displacement', 'force'):
            raise ConfigError(f"rig config: field '{path}.sensor': displacement or force")

    def active(self, t: float) -> bool:
        """True while the fault is active at rig time t [s]."""
        return self.start <= t < self.start + self.duration


@dataclass
class SimOptions:
    """Simulated servo-hydraulic rig. SI units.

    specimen: element-model spec for rubber_rig.models.build_model (default seed-000 at 20 degC), or
    {"model": "linear", "stiffness": N/m, "damping": N s/m}. The actuator is a second-order position loop
    (natural frequency [Hz], damping ratio) with a velocity limit [m/s]. Sensors: noise (std), offset,
    resolution; temperature [degC]. host_timeout [s]: host heartbeat silence after which the controller ramps
    to rest on its own."""
    specimen: dict = field(default_factory=lambda: {'model': 'seed000', 'temperature': 20.0})
    actuator_frequency: float = 80.0
    actuator_damping: float = 0.8
    actuator_velocity_max: float = 0.5
    displacement_noise: float = 0.2e-6
    displacement_offset: float = 0.0
    displacement_resolution: float = 1e-7
    force_noise: float = 2.0
    force_offset: float = 0.0
    force_resolution: float = 0.01
    temperature: float = 20.0
    temperature_noise: float = 0.02
    host_timeout: float = 0.5
    seed: int = 0
    faults: List[FaultSpec] = field(default_factory=list)

    def check(self, path='sim'):
        if not isinstance(self.specimen, dict):
            raise ConfigError(f"rig config: field '{path}.specimen': expected a mapping like "
                              "{model: seed000, temperature: 20.0}")
        positive = ('actuator_frequency', 'actuator_damping', 'actuator_velocity_max', 'displacement_resolution',
                    'force_resolution', 'host_timeout')
        for name in positive:
            if getattr(self, name) <= 0:
                raise ConfigError(f"rig config: field '{path}.{name}': must be > 0")
        for name in ('displacement_noise', 'force_noise', 'temperature_noise'):
            if getattr(self, name) < 0:
                raise ConfigError(f"rig config: field '{path}.{name}': must be >= 0")
        for i, f in enumerate(self.faults):
            f.check(f'{path}.faults[{i}]')


@dataclass
class RigConfig:
    """How to reach the rig.

    backend: "sim" (simulated rig in this process on python-can's virtual bus) or a python-can interface
    name ("socketcan", "pcan", "vector", "kvaser", "virtual", "udp_multicast", ...) with `channel`, bitrates
    and extra `bus_options` passed to can.Bus. spawn_sim: with an interface backend, also start the simulated
    rig as a separate process on that bus. sample_rate [Hz]; watchdog_timeout [s]: feedback/heartbeat silence
    that faults the rig; heartbeat_period [s]; bus_error_max: bad frames (lost, late, malformed) per second of
    samples that fault the bus; lost_burst_max [s]: longest run of lost samples tolerated. stream_timeout [s]:
    a running program's setpoint stream that is silent this long (or runs dry before its last batch) is lost:
    the rig ramps to rest_position [m] (stream_loss_action 'ramp') or stops and holds where it can
    ('hold'), with a stream fault either way. paced: the simulated
    rig runs in real time (True) or as fast as setpoints arrive (False) - identical waveform and physics.
    """
    backend: str = 'sim'
    channel: Optional[str] = None
    bitrate: int = 1_000_000
    data_bitrate: int = 5_000_000
    fd: bool = True
    bus_options: dict = field(default_factory=dict)
    sample_rate: float = 1000.0
    watchdog_timeout: float = 0.1
    heartbeat_period: float = 0.05
    bus_error_max: int = 20
    lost_burst_max: float = 0.02
    stream_timeout: float = 0.3
    stream_loss_action: str = 'ramp'
    rest_position: float = 0.0
    limits: Limits = field(default_factory=Limits)
    paced: bool = True
    spawn_sim: bool = False
    sim: SimOptions = field(default_factory=SimOptions)

    @classmethod
    def from_dict(cls, data) -> 'RigConfig':
        """Validated RigConfig from a mapping (YAML/JSON/ROS parameters). Raises ConfigError naming the field."""
        if isinstance(data, RigConfig):
            data.check()
            return data
        cfg = _build(cls, data or {}, '')
        cfg.check()
        return cfg

    def to_dict(self) -> dict:
        return asdict(self)

    def check(self):
        """Validate value ranges; raise ConfigError naming the field."""
        if not isinstance(self.backend, str) or not self.backend:
            raise ConfigError("rig config: field 'backend': 'sim' or a python-can interface name")
        if self.backend != 'sim':
            import can
            if self.backend not in can.interfaces.VALID_INTERFACES:
                raise ConfigError(f"rig config: field 'backend': unknown python-can interface {self.backend!r} "
                                  f"(use 'sim' or one of: {', '.join(sorted(can.interfaces.VALID_INTERFACES))})")
        if not 10 <= self.sample_rate <= 20000:
            raise ConfigError(f"rig config: field 'sample_rate': {self.sample_rate!r} Hz outside 10..20000")
        for name in ('watchdog_timeout', 'heartbeat_period', 'lost_burst_max'):
            if not getattr(self, name) > 0:
                raise ConfigError(f"rig config: field '{name}': must be > 0")
        if self.heartbeat_period >= self.watchdog_timeout:
            raise ConfigError("rig config: field 'heartbeat_period': must be shorter than watchdog_timeout")
        if not self.stream_timeout > 0:
            raise ConfigError("rig config: field 'stream_timeout': must be > 0")
        if self.stream_loss_action not in ('ramp', 'hold'):
            raise ConfigError(f"rig config: field 'stream_loss_action': 'ramp' or 'hold', got "
                              f"{self.stream_loss_action!r}")
        if not self.limits.displacement_min <= self.rest_position <= self.limits.displacement_max:
            raise ConfigError(f"rig config: field 'rest_position': {self.rest_position:g} m outside the "
                              "displacement limits")
        if self.bus_error_max < 0:
            raise ConfigError("rig config: field 'bus_error_max': must be >= 0")
        self.sim.check()


def _build(cls, data, path):
    """Dataclass `cls` from mapping `data`, type-checked field by field (errors name the dotted path)."""
    where = path or 'rig config'
    if not isinstance(data, dict):
        raise ConfigError(f"rig config: field '{where}': expected a mapping, got {type(data).__name__}")
    known = {f.name: f for f in fields(cls)}
    kwargs = {}
    for key, value in data.items():
        fpath = f'{path}.{key}' if path else key
        if key not in known:
            raise ConfigError(f"rig config: field '{fpath}': unknown (known: {', '.join(sorted(known))})")
        kwargs[key] = _convert(known[key].type, value, fpath)
    return cls(**kwargs)


def _convert(typ, value, fpath):
    typ = typ if isinstance(typ, str) else getattr(typ, '__name__', str(typ))
    bad = ConfigError(f"rig config: field '{fpath}': expected {typ}, got {value!r}")
    if typ == 'Limits':
        try:
            return Limits.from_dict(value)
        except LimitError as exc:
            raise ConfigError(f"rig config: field '{fpath}': {exc}") from None
    if typ == 'SimOptions':
        return _build(SimOptions, value, fpath)
    if typ == 'List[FaultSpec]':
        if not isinstance(value, list):
            raise bad
        return [_build(FaultSpec, v, f'{fpath}[{i}]') for i, v in enumerate(value)]
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
