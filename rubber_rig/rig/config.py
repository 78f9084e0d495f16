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

"""Rig configuration: which bus, which rate, which limits, and the simulated rig's options.

`RigConfig.from_dict` validates everything before anything is opened or sent; errors name the field
(e.g. "rig config: field 'sim.faults[1].type': ...").
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Optional

import can
import yaml

from ..safety import Limits
from ..settings import setting, violations
from .can.canlog import CanLogError, log_format
from .can.frames import PROFILES, default_profile
from .can.protocol import cycle_time
from .can.timing import protocol_load
from .options import ConfigError, SimOptions, _build


class BusLoadError(ConfigError):
    """The configured bus cannot carry the protocol at sample_rate within max_bus_load (field 'sample_rate')."""


@dataclass
class RigConfig:
    """How to reach the rig.

    backend: "sim" (simulated rig in this process; paced, on a simulated bus with the configured bitrates, frame
    timing, arbitration and transmit queues of tx_queue frames (rubber_rig.rig.can.simbus); unpaced, on
    python-can's virtual bus, which has no time) or a python-can interface
    name ("socketcan", "pcan", "vector", "kvaser", "virtual", "udp_multicast", ...) with `channel`, bitrates
    and extra `bus_options` passed to can.Bus. spawn_sim: with an interface backend, also start the simulated
    rig as a separate process on that bus. sample_rate [Hz]; watchdog_timeout [s]: feedback/heartbeat silence
    that faults the rig; heartbeat_period [s]; bus_error_max: bad frames (lost, late, malformed) per second of
    samples that fault the bus; lost_burst_max [s]: longest run of lost samples tolerated. stream_timeout [s]:
    a running program's setpoint stream that is silent this long while less than this much of setpoints is
    queued ahead of the rig (or that runs dry before its last batch) is lost:
    the rig ramps to rest_position [m] (stream_loss_action 'ramp') or stops and holds where it can
    ('hold'), with a stream fault either way. paced: the simulated
    rig runs in real time (True) or as fast as setpoints arrive (False) - identical waveform and physics.
    can_log: file the driver logs every CAN frame it sends and receives to ('' = off; rubber_rig.rig.can.canlog).
    load_cell_delay [s], load_cell_gain [-]: the load cell's calibration, what the lab knows about it (it reads
    gain x the force of delay s earlier), with their standard uncertainties load_cell_delay_u, load_cell_gain_u
    (negative: not declared): recorded in the recording's metadata (rig_config) and applied by `rubber-rig fit`,
    which carries the uncertainties into each parameter's budget; they change nothing on the rig (the simulated
    load cell is sim.force_delay/force_gain). Likewise displacement_gain [-] and displacement_gain_u (the
    displacement transducer reads gain x the displacement) and temperature_u [K] (the temperature sensor).
    max_bus_load: the bus (bitrate, data_bitrate, fd; the simulated rig stands for the same bus) must carry the
    protocol at sample_rate within this load (rubber_rig.rig.can.timing), or the configuration is refused.
    """

    backend: str = setting('sim', "'sim' (simulated rig on python-can's virtual bus) or a python-can interface "
                           'name (socketcan, pcan, vector, kvaser, virtual, udp_multicast, ...)')
    channel: Optional[str] = setting(None, 'python-can channel (e.g. can0, PCAN_USBBUS1); empty: interface default',
                                     name='can.channel', empty_is_none=True)
    bitrate: int = setting(1_000_000, 'CAN (arbitration) bitrate', units='bit/s', range=(10_000, 1_000_000),
                           name='can.bitrate')
    data_bitrate: int = setting(5_000_000, 'CAN FD data bitrate', units='bit/s', range=(10_000, 12_000_000),
                                name='can.data_bitrate')
    fd: bool = setting(True, 'use CAN FD frames', name='can.fd')
    profile: str = setting('', "frames that carry the samples: 'packed' (CAN FD, several samples per frame), "
                           "'single' (CAN FD, one sample per frame), 'classic' (8-byte classic CAN frames); empty: "
                           'packed on CAN FD, classic on classic CAN', choices=('', ) + PROFILES, name='can.profile')
    bus_timing: bool = setting(True, 'paced sim backend: frames take the time the configured bus needs, in '
                               'identifier-priority order (false: python-can virtual bus, every frame at once)',
                               name='can.bus_timing')
    tx_queue: int = setting(1000, 'frames each node of the simulated bus holds waiting for the bus (its transmit '
                            'queue, like SocketCAN txqueuelen; a full queue refuses frames: the driver keeps them, '
                            'the controller loses them)',
                            range=(1, 100000), name='can.tx_queue')
    max_bus_load: float = setting(0.7, 'highest bus load the protocol may need at sample_rate (worst-case bit '
                                  'stuffing); a faster rate is refused before the bus opens', range=(0.05, 1.0),
                                  name='can.max_load')
    bus_options: dict = setting(doc='extra keyword arguments for can.Bus (YAML/JSON mapping)', name='can.bus_options',
                                yaml_text=True, default_factory=dict)
    sample_rate: float = setting(1000.0, 'rig sample rate', units='Hz', range=(10.0, 20000.0))
    watchdog_timeout: float = setting(0.1, 'feedback/heartbeat silence that faults the rig', units='s',
                                      range=(0.005, 10.0))
    heartbeat_period: float = setting(cycle_time('HostHeartbeat'), 'host heartbeat period (default: the DBC cycle '
                                      'time of HostHeartbeat)', units='s', range=(0.001, 5.0))
    bus_error_max: int = setting(20, 'bad frames per second of samples that fault the bus', range=(0, 100000))
    lost_burst_max: float = setting(0.02, 'longest run of lost samples tolerated', units='s', range=(1e-4, 10.0))
    stream_timeout: float = setting(0.15, "a running program's setpoint stream silent this long, with less than this "
                                    'much of setpoints queued ahead of the rig, is lost (the rig ramps to rest, or '
                                    'holds: stream_loss_action); a stall of the owner that its queue covers is '
                                    'not', units='s', range=(0.01, 10.0))
    stream_loss_action: str = setting('ramp', "what a lost stream does: 'ramp' to rest_position or 'hold' where the "
                                      'motion can stop (a stream fault either way)', choices=('ramp', 'hold'))
    rest_position: float = setting(0.0, 'where aborts and faults ramp to', units='m', range=(-1.0, 1.0))
    limits: Limits = setting(doc='safe envelope', nested=Limits, default_factory=Limits)
    paced: bool = setting(True, 'simulated rig runs in real time (false: as fast as setpoints arrive)')
    spawn_sim: bool = setting(False, 'with a python-can interface: also run the simulated rig as a separate '
                              'process on that bus')
    can_log: str = setting('', 'raw CAN log: every frame the driver sends and receives, written by python-can '
                           '(format by suffix: .blf Vector BLF, .asc Vector ASC, .log candump -L); empty: off')
    require_identity: bool = setting(True, 'stream only to a controller that identified itself (ControllerIdentity) '
                                     'with the protocol version of this rubber_rig.dbc')
    controller_device: int = setting(0, 'device code the controller must state in ControllerIdentity (0: any)',
                                     range=(0, 65535))
    load_cell_delay: float = setting(0.0, "the load cell's known delay (it reads the force of this long ago): "
                                     'recorded in the metadata, applied by rubber-rig fit', units='s',
                                     range=(0.0, 0.1))
    load_cell_gain: float = setting(1.0, "the load cell's known gain (it reads gain x the force): recorded in "
                                    'the metadata, applied by rubber-rig fit', units='-', range=(0.01, 100.0))
    load_cell_gain_u: float = setting(-1.0, 'standard uncertainty of load_cell_gain from its calibration '
                                      'certificate (GUM Type B; a class 0.5 load cell, +-0.5 % of reading read as '
                                      'a rectangular distribution: 0.0029); rubber-rig fit adds it to the '
                                      "uncertainty budget of every force-scaled parameter; negative: not declared",
                                      units='-', range=(-1.0, 1.0))
    load_cell_delay_u: float = setting(-1.0, 'standard uncertainty of load_cell_delay (its measurement); '
                                       'rubber-rig fit adds its effect to the uncertainty budget; negative: not '
                                       'declared', units='s', range=(-1.0, 0.1))
    displacement_gain: float = setting(1.0, "the displacement transducer's known gain (it reads gain x the "
                                       'displacement): recorded in the metadata, applied by rubber-rig fit', units='-',
                                       range=(0.01, 100.0))
    displacement_gain_u: float = setting(-1.0, 'standard uncertainty of displacement_gain (calibration certificate, '
                                         'GUM Type B); rubber-rig fit adds it to the budget of every parameter with '
                                         'a length in its unit; negative: not declared', units='-',
                                         range=(-1.0, 1.0))
    temperature_u: float = setting(-1.0, "standard uncertainty of the temperature sensor's reading: the identified "
                                   'parameters belong to the measured temperature +- this; negative: not declared',
                                   units='K', range=(-1.0, 50.0))
    sim: SimOptions = setting(doc='simulated rig', nested=SimOptions, default_factory=SimOptions)

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
            raise ConfigError('backend', "'sim' or a python-can interface name")
        if self.backend != 'sim':
            if self.backend not in can.interfaces.VALID_INTERFACES:
                raise ConfigError('backend', f"unknown python-can interface {self.backend!r} "
                                  f"(use 'sim' or one of: {', '.join(sorted(can.interfaces.VALID_INTERFACES))})")
        for path, why in violations(self):                 # ranges and choices, as each setting() describes them
            raise ConfigError(path, why)
        for name in ('watchdog_timeout', 'heartbeat_period', 'lost_burst_max'):
            if not getattr(self, name) > 0:
                raise ConfigError(name, "must be > 0")
        if self.heartbeat_period >= self.watchdog_timeout:
            raise ConfigError('heartbeat_period', "must be shorter than watchdog_timeout")
        if not self.stream_timeout > 0:
            raise ConfigError('stream_timeout', "must be > 0")
        if not self.limits.displacement_min <= self.rest_position <= self.limits.displacement_max:
            raise ConfigError('rest_position', f"{self.rest_position:g} m outside the "
                              "displacement limits")
        if self.bus_error_max < 0:
            raise ConfigError('bus_error_max', "must be >= 0")
        if not 0 <= self.load_cell_delay <= 0.1:
            raise ConfigError('load_cell_delay', f"{self.load_cell_delay!r} s outside 0..0.1")
        if not (math.isfinite(self.load_cell_gain) and self.load_cell_gain > 0):
            raise ConfigError('load_cell_gain', f"must be > 0, got {self.load_cell_gain!r}")
        self._check_bus_load()
        if self.can_log:
            try:
                log_format(self.can_log)
            except CanLogError as exc:
                raise ConfigError('can_log', str(exc)) from None
        self.sim.check()
        if any(f.type == 'bus_flood' for f in self.sim.faults) and not (self.backend == 'sim' and self.paced
                                                                        and self.bus_timing):
            raise ConfigError('sim.faults', 'bus_flood needs the timed bus of the paced sim backend (backend sim, '
                              'paced true)')

    @property
    def frame_profile(self) -> str:
        """The frame profile in use (profile, or the bus's default when profile is empty)."""
        return self.profile or default_profile(self.fd)

    def bus_load(self):
        """The protocol's load on the configured bus at sample_rate (rubber_rig.rig.can.timing.BusLoad)."""
        return protocol_load(self.sample_rate, self.bitrate, self.data_bitrate if self.fd else None, fd=self.fd,
                             profile=self.frame_profile)

    def _check_bus_load(self):
        if not 0 < self.max_bus_load <= 1:
            raise ConfigError('max_bus_load', f'must be within (0, 1], got {self.max_bus_load!r}')
        if self.profile not in ('',) + PROFILES:
            raise ConfigError('profile', f"{self.profile!r}: one of {', '.join(PROFILES)} (or empty)")
        try:
            load = self.bus_load()
        except ValueError as exc:
            raise ConfigError('profile' if self.profile else 'fd', str(exc)) from None
        if load.load > self.max_bus_load:
            bus = (f'{self.bitrate / 1e6:g}/{self.data_bitrate / 1e6:g} Mbit/s CAN FD' if self.fd
                   else f'{self.bitrate / 1e6:g} Mbit/s classic CAN')
            raise BusLoadError('sample_rate', f'{self.sample_rate:g} Hz needs {load.load * 100:.0f} % of the {bus} '
                               f'bus with {self.frame_profile} frames, more than max_bus_load '
                               f'({self.max_bus_load * 100:.0f} %): this bus carries at most '
                               f'{load.rate_at(self.max_bus_load):.0f} Hz')


def configuration_text(config: RigConfig) -> str:
    """YAML of the rig facts every recording carries (the recorder records the rig_driver's latched
    ``rig_configuration`` topic): sample rate, backend, and the load cell's declared calibration with its
    standard uncertainties, which ``rubber-rig fit`` applies and puts in its uncertainty budget.
    """
    facts = {k: v for k, v in asdict(config).items() if isinstance(v, (int, float, str, bool))}
    return yaml.safe_dump(facts, sort_keys=True)
