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

"""open_rig: the driver on the configured bus, plus the simulated rig behind it when asked for (like python-can's
can.interface, it picks the backend from the configuration).
"""
import json
import subprocess
import sys
import time

from .can.bus import open_bus, sim_channel_name
from .can.canlog import LOG_CHANNEL_SIM, CanLogError, CanLogTap, LoggingBus
from .can.driver import RigDriver
from .can.protocol import Protocol
from .can.simbus import BusMedium
from .config import ConfigError, RigConfig
from .sim.controller import SimController


class Rig:
    """An open rig: `driver` (RigDriver) plus, for the "sim" backend, the in-process simulated controller
    (`sim`) on the other end of the same virtual bus, or a spawned simulator process (`process`).
    A paced in-process simulator runs in a thread; an unpaced one is advanced by driver.poll().
    `can_log`: the CanLogTap writing the driver's frames (config.can_log), or None. `medium`: the simulated bus
    with bit timing of a paced "sim" rig (rubber_rig.rig.can.simbus.BusMedium), or None.
    """

    def __init__(self, config: RigConfig, driver: RigDriver, sim=None, sim_bus=None, process=None, can_log=None,
                 medium=None):
        self.config, self.driver, self.sim, self._sim_bus, self.process = config, driver, sim, sim_bus, process
        self.can_log = can_log
        self.medium = medium   # the simulated bus with timing (BusMedium), or None

    def wait_ready(self, timeout: float = 10.0) -> bool:
        """Poll until the controller has announced itself (state no longer 'unconfigured') and its heartbeat,
        status and, where the configuration requires it, identity (ControllerIdentity) have each been heard
        within their silence limits (Supervisor.why_not_heard); wall timeout [s].
        """
        deadline = time.monotonic() + timeout
        d = self.driver
        while time.monotonic() < deadline:
            d.poll()
            if d.controller_state != 'unconfigured' and not d.supervisor.why_not_heard():
                return True
            time.sleep(0.002)
        return False

    def close(self):
        """Stop the simulator (thread or process), shut both bus ends down and close the raw CAN log."""
        if self.sim is not None:
            self.sim.stop()
            if self.sim.flood_bus is not None:
                self.sim.flood_bus.shutdown()
        if self.process is not None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
        try:
            self.driver.close()
        finally:
            if self.can_log is not None:   # also when the bus failed on the way down
                self.can_log.close()
        if self._sim_bus is not None:
            self._sim_bus.shutdown()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def open_rig(config) -> Rig:
    """Open the rig described by `config` (RigConfig or mapping; validated first, nothing is opened on error).

    backend "sim": simulated controller in a thread on a simulated bus of the configured bitrates (paced; frames
    take their time, rubber_rig.rig.can.simbus) or on a fresh python-can virtual channel (unpaced). Any other backend:
    the driver on that python-can interface; with spawn_sim, the simulated rig is started as a separate process
    (python -m rubber_rig.rig.sim) on the same bus and the call waits until it answers.

    can_log: the raw CAN log is created before the bus is opened (ConfigError naming 'can_log' if it cannot be
    written) and closed with the rig.
    """
    cfg = RigConfig.from_dict(config)
    proto = Protocol()
    tap = _open_can_log(cfg)
    try:
        rig = _open(cfg, proto, tap)
    except BaseException:
        if tap is not None:
            tap.close()
            if not tap.frames_tx + tap.frames_rx:   # nothing was logged: leave no empty log behind
                tap.path.unlink(missing_ok=True)
        raise
    if tap is not None:
        driver = rig.driver
        tap.on_error = lambda text: driver.events.append(('warn', text))   # reported once, by the node's log
        driver.events.append(('info', f'raw CAN log: every frame sent and received goes to {tap.path}'))
    return rig


def _open_can_log(cfg: RigConfig):
    if not cfg.can_log:
        return None
    if cfg.channel not in (None, ''):
        channel = str(cfg.channel)
    else:
        channel = LOG_CHANNEL_SIM if cfg.backend == 'sim' else f'{cfg.backend}0'
    try:
        return CanLogTap(cfg.can_log, channel)
    except CanLogError as exc:
        raise ConfigError('can_log', str(exc)) from None


def _open(cfg: RigConfig, proto: Protocol, tap) -> Rig:
    logged = (lambda bus: LoggingBus(bus, tap)) if tap is not None else (lambda bus: bus)
    if cfg.backend == 'sim':
        medium = flood = None
        if cfg.paced and cfg.bus_timing:   # real time: frames take the time the configured bus needs for them
            medium = BusMedium(cfg.bitrate, cfg.data_bitrate, cfg.fd, tx_queue=cfg.tx_queue, name=sim_channel_name())
            bus, sim_bus = medium.attach('host'), medium.attach('controller')
            if any(f.type == 'bus_flood' for f in cfg.sim.faults):
                flood = medium.attach('flood')
        else:   # as fast as possible (no time, so no bus timing) or asked for: python-can's virtual bus
            channel = sim_channel_name()
            bus, sim_bus = open_bus(cfg, channel), open_bus(cfg, channel)
        try:
            sim = SimController(sim_bus, cfg.sample_rate, cfg.sim, cfg.paced, proto,   # may raise ConfigError
                                profile=cfg.frame_profile, flood_bus=flood)
        except Exception:
            bus.shutdown()
            sim_bus.shutdown()
            raise
        driver = RigDriver(logged(bus), cfg, proto)
        if medium is not None:
            driver.measured_load = medium.load
        if cfg.paced:
            # real time: the simulator keeps its own clock in a thread; the time this host keeps it from its
            # deadlines is this host's lateness, never the rig's silence (rig.sim.lateness). Not while it also plays
            # a flooding node (bus_flood): then its own work for that node makes it late (0.6 s of 1 s in
            # test_bus_overload_mid_run_faults_safely_and_counts_the_loss), which a real controller would not be
            if flood is None:
                driver.supervisor.host_lateness = sim.lateness.lag
            sim.start()
        else:
            driver.pump = sim.pump   # as fast as possible: the driver's poll() lets the simulator catch up
        rig = Rig(cfg, driver, sim=sim, sim_bus=sim_bus, can_log=tap, medium=medium)
    else:
        process = None
        if cfg.spawn_sim:
            process = subprocess.Popen([sys.executable, '-m', 'rubber_rig.rig.sim', '--config-json',
                                        json.dumps(cfg.to_dict())],
                                       stdout=subprocess.DEVNULL)
        bus = open_bus(cfg)
        rig = Rig(cfg, RigDriver(logged(bus), cfg, proto), process=process, can_log=tap)
        if process is not None and not rig.wait_ready(20.0):
            rig.close()
            raise ConfigError('spawn_sim', 'the simulated rig process did not answer on '
                              f'{cfg.backend} {cfg.channel or ""} within 20 s')
    return rig
