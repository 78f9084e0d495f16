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

"""The parameters of rig_driver: declared from the core's settings (RigConfig, described once) plus the node's
own, turned into a RigConfig, and applied at run time (RigDriverParameters, a part of RigDriverNode).

A sample_rate the CAN bus cannot carry (at can.bitrate / can.data_bitrate with the frame profile, within
can.max_load) does not end the process: configure fails with one error line naming sample_rate, the bus and its
bitrates, the load the rate needs and the highest rate the bus carries, and the node stays up and unconfigured,
its status saying so; ``ros2 param set`` a rate that fits (accepted while unconfigured) and configure again.
What the bus carries is, like whether the bus is there at all, a question about the bus configure opens. Values
wrong in themselves or contradicting each other (a range, limits, heartbeat_period >= watchdog_timeout, a fault
list that does not parse) are refused at start: one FATAL line naming the parameter, exit status 2
(rubber_rig.nodes.spin); set at run time while unconfigured, they make configure fail the same way.

At run time the limits and the stream settings apply at once (rubber_rig.rig.live); every other setting of the
core needs configure, and is refused while the rig is configured.
"""
from __future__ import annotations

from rcl_interfaces.msg import SetParametersResult

from rubber_rig.nodes.params import ParameterError, declare
from rubber_rig.rig.config import BusLoadError, ConfigError, RigConfig
from rubber_rig.rig.live import LIMIT_SETTINGS, LIVE_SETTINGS, PROTECTIVE_SETTINGS, RIG_SETTINGS, apply_live, weakening
from rubber_rig.safety import LimitError, Limits
from rubber_rig.settings import nest, setting_for

__all__ = ['BATCH_PERIOD', 'LIVE_PARAMETERS', 'RIG_SETTINGS', 'BusCapacityError', 'RigDriverParameters']

BATCH_PERIOD = 0.01   # [s] default length of a sample batch (batch_size 0)
# parameters the running driver applies at once (the core's LIVE_SETTINGS) and the node's own; every other one
# needs configure (refused while configured)
LIVE_PARAMETERS = LIVE_SETTINGS | {'batch_size', 'max_batch_delay', 'status_period', 'diagnostics_period', 'autostart',
                                   'owner_timeout'}
# the simulated specimen: node parameters built into SimOptions.specimen (a model spec mapping)
SPECIMEN_PARAMETERS = ('sim.specimen.parameter_set', 'sim.specimen.temperature',
                       'sim.specimen.friction_reversal_threshold')


class BusCapacityError(ParameterError):
    """sample_rate is more than the configured CAN bus carries (the node stays up, unconfigured)."""


class RigDriverParameters:
    """The parameter side of RigDriverNode (which provides rig, config, peers, publish_status, _log_events)."""

    def _declare_parameters(self) -> None:
        self.autostart = declare(self, 'autostart', True, 'configure and activate at start')
        for setting in RIG_SETTINGS:
            declare(self, setting.name, setting.default, setting.description(), range=setting.range,
                    choices=setting.choices)
        self.batch_size = declare(self, 'batch_size', 0, 'samples per RigSampleBatch message (at least; whole bus '
                                  'reads are never split, so the stamp is the bus time of the first sample); 0: '
                                  f'{BATCH_PERIOD * 1e3:g} ms of samples, which keeps a prediction within 25 ms of '
                                  'its sample at 1 kHz', range=(0, 10000))
        self.max_batch_delay = declare(self, 'max_batch_delay', 0.1, 'a partial batch is published when its '
                                       'first sample has waited this long (the stream paused or ended)',
                                       range=(0.001, 10.0), units='s')
        declare(self, 'poll_period', 0.002, 'how often the bus is read (a sample waits up to this long)',
                range=(0.0005, 0.5), units='s')
        declare(self, 'sim.specimen.parameter_set', '', 'simulated specimen: fractional_zener_berg parameter set '
                '(empty: use sim.specimen.temperature)')
        declare(self, 'sim.specimen.temperature', 20.0, 'simulated specimen: fractional_zener_berg parameters at this '
                'temperature', range=(-40.0, 20.0), units='degC')
        declare(self, 'sim.specimen.friction_reversal_threshold', 0.0, "simulated specimen: Berg reversal deadband "
                "on its true displacement (0 = the paper's rule)", range=(0.0, 1e-4), units='m')
        self.status_period = declare(self, 'status_period', 0.1, 'status publishing period', range=(0.01, 10.0),
                                     units='s')
        self.diagnostics_period = declare(self, 'diagnostics_period', 1.0, 'diagnostics period',
                                          range=(0.1, 60.0), units='s')
        self.owner_timeout = declare(self, 'owner_timeout', 1.0, "the stream owner's heartbeat silent this long "
                                     'is stream loss, also while it holds the rig (an owner that never beat, '
                                     'e.g. a script without one, is watched by stream_timeout alone)',
                                     range=(0.3, 30.0), units='s')
        # the authority on how far the rig may go: the values it was started with (its configuration file);
        # run time may make them stricter, and relax them back only this far (rig.live.weakening)
        self.configured_protection = {name: self.get_parameter(name).value for name in PROTECTIVE_SETTINGS}
        self.refused_weakening = 0       # run-time parameter changes refused by that rule (diagnostics)

    # -- parameters -> core configuration ---------------------------------------------------------------
    def rig_config(self) -> RigConfig:
        """The core configuration from the parameters; ParameterError names the parameter a bad value is in."""
        values = {}
        for setting in RIG_SETTINGS:
            try:
                values[setting.path] = setting.value(self.get_parameter(setting.name).value)
            except ValueError as exc:
                raise ParameterError(self, setting.name, str(exc)) from None
        p = {name: self.get_parameter(name).value for name in SPECIMEN_PARAMETERS}
        specimen = ({'model': 'fractional_zener_berg', 'parameter_set': p['sim.specimen.parameter_set']}
                    if p['sim.specimen.parameter_set'] else
                    {'model': 'fractional_zener_berg', 'temperature': p['sim.specimen.temperature']})
        specimen['friction_reversal_threshold'] = p['sim.specimen.friction_reversal_threshold']
        values['sim.specimen'] = specimen
        try:
            return RigConfig.from_dict(nest(values))
        except ConfigError as exc:   # names the field: the parameter is the setting it belongs to
            setting = setting_for(RIG_SETTINGS, exc.field)
            name = setting.name if setting else (
                'sim.specimen.parameter_set' if exc.field.startswith('sim.specimen') else exc.field)
            # the field's own message when the field is the parameter; a deeper field ('sim.faults[1].type') is named
            why = exc.why if exc.field in (name, setting and setting.path) else str(exc)
            raise (BusCapacityError if isinstance(exc, BusLoadError) else ParameterError)(self, name, why) from None

    @property
    def samples_per_batch(self) -> int:
        """batch_size, or BATCH_PERIOD of samples at the configured rate when it is 0."""
        return self.batch_size or max(1, round(BATCH_PERIOD * self.config.sample_rate))

    def asked_limits(self) -> Limits:
        """The limits the parameters ask for, when they make no configuration (configure says why)."""
        try:
            return Limits(**{n.split('.', 1)[1]: float(self.get_parameter(n).value) for n in LIMIT_SETTINGS})
        except (LimitError, TypeError, ValueError):
            return Limits()

    # -- parameters at run time -------------------------------------------------------------------------------
    def on_set_parameters(self, params) -> SetParametersResult:
        """Limits and stream settings apply at once (tighter limits: the rig ramps into them if it must);
        everything else needs configure, so it is refused while the rig is configured, with the reason.
        """
        changed = {p.name: p.value for p in params}
        stream_open = self.rig is not None and bool(self.rig.driver.status.extra.get('stream_owner'))
        current = {name: self.get_parameter(name).value for name in PROTECTIVE_SETTINGS}
        why = weakening(changed, current, self.configured_protection, stream_open)
        if why:
            self.refused_weakening += 1
            self.get_logger().warning(f'parameter change refused: {why}')
            return SetParametersResult(successful=False, reason=why)
        fixed = sorted(n for n in changed if n not in LIVE_PARAMETERS)
        if fixed and self.rig is not None:
            return SetParametersResult(successful=False, reason=f"{', '.join(fixed)}: applied at configure; the "
                                       'rig is configured (deactivate and clean up first)')
        if self.config is None:   # no configuration in force: configure checks all parameters together
            if 'batch_size' in changed:
                self.batch_size = int(changed['batch_size'])
            if 'max_batch_delay' in changed:
                self.max_batch_delay = float(changed['max_batch_delay'])
            return SetParametersResult(successful=True)
        why, limits = apply_live(self.config, changed)
        if why:
            return SetParametersResult(successful=False, reason=why)
        if 'batch_size' in changed:
            self.batch_size = int(changed['batch_size'])
        if 'max_batch_delay' in changed:
            self.max_batch_delay = float(changed['max_batch_delay'])
        if 'owner_timeout' in changed:
            self.owner_timeout = self.owner_watch.peers.silent_after = float(changed['owner_timeout'])
        if limits is not None:
            if self.rig is not None:
                self.rig.driver.set_limits(limits)
                self._log_events()
            self.publish_status()
        return SetParametersResult(successful=True)
