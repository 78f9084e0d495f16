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
own, read into plain values the node holds (:class:`RigDriverParams`, the core's RigConfig), and judged at run time
(rubber_rig.rig.live.review_change: plain values in, the reason and the new limits out).

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

from dataclasses import dataclass

from rclpy.node import Node

from rubber_rig.nodes.params import ParameterError, declare
from rubber_rig.rig.config import BusLoadError, ConfigError, RigConfig
from rubber_rig.rig.live import LIMIT_SETTINGS, LIVE_SETTINGS, PROTECTIVE_SETTINGS, RIG_SETTINGS
from rubber_rig.safety import LimitError, Limits
from rubber_rig.session.liveness import OWNER_TIMEOUT
from rubber_rig.settings import nest, setting_for

__all__ = ['BATCH_PERIOD', 'LIVE_PARAMETERS', 'RIG_SETTINGS', 'BusCapacityError', 'RigDriverParams', 'asked_limits',
           'declare_rig_driver_parameters', 'protective_values', 'rig_config']

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


@dataclass
class RigDriverParams:
    """rig_driver's own parameters (those RigConfig does not hold), as read from the node's declared parameters.

    autostart: configure and activate at start; batch_size: samples per message (0: BATCH_PERIOD of samples);
    max_batch_delay [s]: a partial batch waits at most this long; receive: 'thread' (a thread blocks on the bus and
    wakes the node once per batch, rig.can.receiver) or 'poll'; poll_period [s]: the bus is read this often (poll);
    status_period, diagnostics_period [s]; owner_timeout [s]: the stream owner's heartbeat silent this long is stream
    loss; nice: the niceness of the rig_driver process (rig.priority);
    configured_protection: the protective settings (limits, timeouts) the node was started with, which run time
    may make stricter and relax back only this far (rig.live.weakening).
    """

    autostart: bool
    batch_size: int
    max_batch_delay: float
    poll_period: float
    status_period: float
    diagnostics_period: float
    owner_timeout: float
    configured_protection: dict
    nice: int = 0
    receive: str = 'thread'

    def samples_per_batch(self, sample_rate: float) -> int:
        """batch_size, or BATCH_PERIOD of samples at ``sample_rate`` [Hz] when it is 0."""
        return self.batch_size or max(1, round(BATCH_PERIOD * sample_rate))

    def apply(self, changed: dict) -> None:
        """Take the node's own live parameters among ``changed`` (name -> value) that review_change accepted."""
        if 'batch_size' in changed:
            self.batch_size = int(changed['batch_size'])
        if 'max_batch_delay' in changed:
            self.max_batch_delay = float(changed['max_batch_delay'])
        if 'owner_timeout' in changed:
            self.owner_timeout = float(changed['owner_timeout'])


def declare_rig_driver_parameters(node: Node) -> RigDriverParams:
    """Declare every parameter of rig_driver on ``node`` (the core's settings and the node's own, with descriptions,
    ranges and units) and return the node's own values.
    """
    autostart = declare(node, 'autostart', True, 'configure and activate at start')
    for setting in RIG_SETTINGS:
        declare(node, setting.name, setting.default, setting.description(), range=setting.range,
                choices=setting.choices)
    batch_size = declare(node, 'batch_size', 0, 'samples per RigSampleBatch message (at least; whole bus reads are '
                         'never split, so the stamp is the bus time of the first sample); 0: '
                         f'{BATCH_PERIOD * 1e3:g} ms of samples, which keeps a prediction within 25 ms of its sample '
                         'at 1 kHz', range=(0, 10000))
    max_batch_delay = declare(node, 'max_batch_delay', 0.1, 'a partial batch is published when its first sample '
                              'has waited this long (the stream paused or ended)', range=(0.001, 10.0), units='s')
    receive = declare(node, 'receive', 'thread', "how the bus is read: 'thread' = a thread waits on the bus and wakes "
                      'the node once per batch of samples (fewest wake-ups; the watchdog still polls at its own '
                      "period), 'poll' = every poll_period (the simulated rig run unpaced is always polled)",
                      choices=('thread', 'poll'))
    poll_period = declare(node, 'poll_period', 0.002, "how often the bus is read with receive 'poll' (a sample waits "
                          'up to this long)', range=(0.0005, 0.5), units='s')
    declare(node, 'sim.specimen.parameter_set', '', 'simulated specimen: fractional_zener_berg parameter set '
            '(empty: use sim.specimen.temperature)')
    declare(node, 'sim.specimen.temperature', 20.0, 'simulated specimen: fractional_zener_berg parameters at this '
            'temperature', range=(-40.0, 20.0), units='degC')
    declare(node, 'sim.specimen.friction_reversal_threshold', 0.0, "simulated specimen: Berg reversal deadband "
            "on its true displacement (0 = the paper's rule)", range=(0.0, 1e-4), units='m')
    status_period = declare(node, 'status_period', 0.1, 'status publishing period', range=(0.01, 10.0), units='s')
    diagnostics_period = declare(node, 'diagnostics_period', 1.0, 'diagnostics period', range=(0.1, 60.0),
                                 units='s')
    owner_timeout = declare(node, 'owner_timeout', OWNER_TIMEOUT, "the stream owner's heartbeat silent this long is "
                            'stream loss, also while it holds the rig (an owner that never beat, e.g. a script without '
                            'one, is watched by stream_timeout alone)', range=(0.3, 30.0), units='s')
    nice = declare(node, 'nice', 0, 'niceness of the rig_driver process, set when it starts as a process of its own '
                   '(rubber_rig.rig.priority): below 0 its bus reads and setpoints get the CPU before the other '
                   "programs of this computer (ros2_control's thread_priority, without a real-time kernel); needs "
                   'root or CAP_SYS_NICE, else a warning and the process keeps its priority', range=(-20, 19))
    return RigDriverParams(autostart, batch_size, max_batch_delay, poll_period, status_period, diagnostics_period,
                           owner_timeout, protective_values(node), nice, receive)


def protective_values(node: Node) -> dict:
    """The node's protective settings now (PROTECTIVE_SETTINGS: name -> value)."""
    return {name: node.get_parameter(name).value for name in PROTECTIVE_SETTINGS}


# -- parameters -> core configuration ---------------------------------------------------------------------------
def rig_config(node: Node) -> RigConfig:
    """The core configuration from ``node``'s parameters; ParameterError names the parameter a bad value is in."""
    values = {}
    for setting in RIG_SETTINGS:
        try:
            values[setting.path] = setting.value(node.get_parameter(setting.name).value)
        except ValueError as exc:
            raise ParameterError(node, setting.name, str(exc)) from None
    p = {name: node.get_parameter(name).value for name in SPECIMEN_PARAMETERS}
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
        raise (BusCapacityError if isinstance(exc, BusLoadError) else ParameterError)(node, name, why) from None


def asked_limits(node: Node) -> Limits:
    """The limits ``node``'s parameters ask for, when they make no configuration (configure says why)."""
    try:
        return Limits(**{n.split('.', 1)[1]: float(node.get_parameter(n).value) for n in LIMIT_SETTINGS})
    except (LimitError, TypeError, ValueError):
        return Limits()
