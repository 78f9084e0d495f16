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

"""rig_driver: lifecycle (managed) node between the CAN bus of the rig and the ROS graph.

Lifecycle (as the ros2/demos lifecycle talker): configure = validate parameters, open the bus they choose (``backend:
sim`` = the simulated rig on python-can's virtual bus, or any python-can interface) and create what works on it (the
samples publisher, the owners' command channels); activate = read the bus: stream samples, accept setpoints;
deactivate = safe ramp to rest, stop reading; cleanup = ramp, close the bus, destroy what configure created. The
bus is read by a thread that wakes the node once per batch (``receive: thread``, rig.can.receiver) or polled every
``poll_period``; status, heartbeat, diagnostics, the watchdog's polls run from the node's one timer (nodes/ticks.py).
Status, diagnostics, heartbeat and services report the state in every state. With ``autostart`` the node configures
and activates itself (what ``ros2 launch`` users expect from a simulated rig). Parameters:
nodes/rig_driver_params.py (what a bad value or a rate the bus cannot carry does), held as ``self.params``.

Subscribes:  ~/setpoint_stream/<owner> (msg_defs/SetpointBatch): each owner's command channel; only the open
             stream's owner commands the rig, with batches signed by the rig key (nodes/auth.py; others are
             refused and counted, named in /diagnostics with their channel). The public
             ``setpoints`` is not read: traffic there (a script, a replayed recording) never moves the rig, and
             no traffic delays the owner's batches (topics.py). heartbeat: the owner's, signed only
Publishes:   samples (msg_defs/RigSampleBatch, signed, at least ``batch_size`` samples per message)
             status (msg_defs/RigStatus, latched, on change and every ``status_period``)
             /diagnostics (diagnostic_msgs/DiagnosticArray, every ``diagnostics_period``)
Services:    ~/open_stream (msg_defs/OpenStream, signed): the right to command the rig; one owner at a time
             ~/stop_stream (msg_defs/StopStream, signed): the owner stops now: abort (ramp to rest) or hold
             ~/abort (std_srvs/Trigger): safe ramp to rest now, whoever streams
             ~/reset (std_srvs/Trigger): acknowledge and clear faults once the rig is at rest. QoS: topics.py

The driver is the one safety authority: the watchdog, the limits (changeable at run time: applied at once),
stream ownership and stream-loss detection, fault detection and the safe ramp are the core driver's
(rubber_rig.rig); this node moves data between it and ROS and logs every transition it reports.
"""
from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from std_msgs.msg import String
from std_srvs.srv import Trigger

from msg_defs.msg import RigSampleBatch, RigStatus, SetpointBatch
from msg_defs.srv import OpenStream, StopStream
from rubber_rig.cpu import RECEIVE_THREAD, name_this_thread
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes import rig_driver_services as services
from rubber_rig.nodes import topics
from rubber_rig.nodes.auth import SAMPLES, SETPOINT_STREAM, annotate, declare_auth
from rubber_rig.nodes.heartbeat import (
    PERIOD,
    OwnerSilence,
    OwnerWatch,
    Peers,
    annotate_owner_silence,
    start_heartbeat,
)
from rubber_rig.nodes.params import ParameterError, accept_integers_for_doubles
from rubber_rig.nodes.rclpy_compat import lifecycle_state
from rubber_rig.nodes.rig_driver_channels import CommandChannels
from rubber_rig.nodes.rig_driver_params import (  # noqa: F401 - also imported from here
    BATCH_PERIOD,
    LIVE_PARAMETERS,
    RIG_SETTINGS,
    BusCapacityError,
    asked_limits,
    declare_rig_driver_parameters,
    protective_values,
    rig_config,
)
from rubber_rig.nodes.spin import spin_node, with_process_nice
from rubber_rig.nodes.ticks import NodeTicks
from rubber_rig.rig.can.batcher import SampleBatcher
from rubber_rig.rig.can.gate import StreamGate
from rubber_rig.rig.config import RigConfig, configuration_text
from rubber_rig.rig.interface import open_rig
from rubber_rig.rig.live import review_change
from rubber_rig.rig.shutdown import ramp_to_rest


class RigDriverNode(LifecycleNode):

    events_executor_refuses = 'a guard condition (the bus thread\'s wake-up)'   # nodes.executor_choice

    def __init__(self, node_name: str = 'rig_driver', **kwargs):
        super().__init__(node_name, **kwargs)
        self.params = declare_rig_driver_parameters(self)   # the node's own parameters (RigConfig holds the rig's)
        self.refused_weakening = 0         # run-time parameter changes refused by rig.live.weakening (diagnostics)
        self.auth = declare_auth(self)     # the rig's key: every command must carry its signature (nodes/auth.py)
        try:   # checked now: a bad value fails at start, naming the parameter (spin_node: one line, exit 2) ...
            self.config: RigConfig | None = rig_config(self)
        except BusCapacityError as exc:   # ... except a rate the bus cannot carry: configure fails, node stays up
            self.config = None
            if not self.params.autostart:
                self.get_logger().error(f'{exc}; configure will fail until the parameter is changed')
        # created by configure, destroyed by cleanup
        self.rig = None
        self.gate = None                   # StreamGate of the open rig: who may stream (rig.can.gate)
        self.pub_samples = None
        self._frames_in = None             # guard condition: the receiving thread's frames wake the node
        self.channels: CommandChannels | None = None   # the owners' command channels
        self.batcher = SampleBatcher()     # the driver's sample blocks -> RigSampleBatch messages
        self.active = False                # streaming samples and accepting setpoints
        self._last_status = None
        self._status_key = None
        self.pub_status = self.create_publisher(RigStatus, topics.STATUS, topics.LATCHED_QOS)
        # what a recording must know of this rig (the load cell's declared calibration for rubber-rig fit):
        # latched, so the recorder records it and a file converted by any rosbag2 tool keeps it
        self.pub_configuration = self.create_publisher(String, topics.RIG_CONFIGURATION, topics.LATCHED_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.create_service(Trigger, '~/abort', self.on_abort)
        self.create_service(Trigger, '~/reset', self.on_reset)
        self.create_service(OpenStream, '~/open_stream', lambda req, res: services.open_stream(self, req, res))
        self.create_service(StopStream, '~/stop_stream', lambda req, res: services.stop_stream(self, req, res))
        accept_integers_for_doubles(self)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        beat = start_heartbeat(self, lambda: self.rig.driver.status.state if self.rig else 'unconfigured', timer=False)
        peers = Peers(self, silent=self.params.owner_timeout, auth=self.auth, polled=True)   # owner silent: stream lost
        self.owner_watch, self.owner_silence = OwnerWatch(peers), OwnerSilence(peers)
        self.ticks = NodeTicks(self, {   # one timer: these, and the bus polls while active
            'status': (self.params.status_period, self.publish_status), 'heartbeat': (PERIOD, beat),
            'diagnostics': (self.params.diagnostics_period, self.publish_diagnostics),
            'channels': (1.0, lambda: self.channels is not None and self.channels.find())})
        self.publish_status()
        if self.params.autostart and self.trigger_configure() == TransitionCallbackReturn.SUCCESS:
            self.trigger_activate()
            self.publish_status()   # the latched status says at once what autostart reached, not 'unconfigured'

    @property
    def lifecycle_state(self) -> str:
        """'unconfigured', 'inactive', 'active' or 'finalized'."""
        return lifecycle_state(self)

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.config = rig_config(self)
        except ParameterError as exc:   # parameters that do not work together: stay unconfigured, say why
            self.config = None
            self.get_logger().error(f'configure failed, {self.get_name()} stays unconfigured (set the parameter and '
                                    f'configure again): {exc}')
            return TransitionCallbackReturn.FAILURE
        try:
            self.rig = open_rig(self.config)
            self.gate = StreamGate(self.rig.driver)
            self.channels = CommandChannels(self, self.gate, self.rig.driver, self.on_setpoints)
        except Exception as exc:  # bus not available: stay unconfigured, say why
            self.get_logger().error(f'configure failed, {self.get_name()} stays unconfigured: {exc}')
            return TransitionCallbackReturn.FAILURE
        self.batcher = SampleBatcher()
        self.pub_samples = self.create_lifecycle_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
        self._frames_in = self.create_guard_condition(lambda: self.active and self.ticks.tick_now())   # poll + duties
        self.pub_configuration.publish(String(data=configuration_text(self.config)))
        self.get_logger().info(f'rig open: backend {self.config.backend}, {self.config.sample_rate:g} Hz, '
                               f'{self.params.samples_per_batch(self.config.sample_rate)} samples per batch')
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        driver = self.rig.driver
        if driver.faults or driver.fault_messages:   # activating again is the operator's acknowledgement
            why = driver.reset()
            if why:
                self.get_logger().error(f'activate refused: {why}')
                return TransitionCallbackReturn.FAILURE
        self._start_polling()
        self.active = True
        self.get_logger().info('active: streaming samples, accepting a setpoint stream')
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.rig is not None:
            self.rig.driver.abort('driver deactivated')
            self.log_events()
        self._stop_polling()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:
        """Ramp to rest, close the bus and destroy what configure created (also called by the in-process launcher at
        shutdown): the wait is rubber_rig.rig.shutdown.ramp_to_rest's (at most RAMP_WAIT s; not for a silent
        controller; none when idle).
        """
        self._stop_polling()
        if self._frames_in is not None:
            self.destroy_guard_condition(self._frames_in)
            self._frames_in = None
        if self.channels is not None:
            self.channels.close()
            self.channels = None
        if self.rig is not None:
            rig, self.rig, self.gate = self.rig, None, None
            driver = rig.driver
            outcome = ramp_to_rest(driver, 'rig_driver shutting down')
            if outcome.message:
                self.get_logger().warning(outcome.message)
            self.log_events(driver)
            self.get_logger().info(f'rig closed (controller {driver.controller_state}, at '
                                   f'{driver.status.extra["position"] * 1e3:.4f} mm)')
            rig.close()
        if self.pub_samples is not None:
            self.destroy_lifecycle_publisher(self.pub_samples)
            self.pub_samples = None

    def _start_polling(self) -> None:
        """Poll on the timer's ticks; with receive 'thread' the frames wake the node once per batch and the ticks
        are the watchdog's (a silent bus wakes nobody). Unpaced, the polls drive the simulator: always polled.
        """
        driver = self.rig.driver
        if self.params.receive == 'thread' and driver.pump is None:
            driver.receive_in_thread(self._frames_in.trigger, self.params.samples_per_batch(self.config.sample_rate),
                                     on_start=lambda: name_this_thread(RECEIVE_THREAD))   # (an error: its poll says)
        self.ticks.every_tick(self.poll, driver.tick_period if driver.io.receiver else self.params.poll_period)

    def _stop_polling(self) -> None:
        self.active = False
        self.ticks.every_tick(None)
        if self.rig is not None:
            self.rig.driver.io.stop_receiving()   # (what it read is taken now; later frames wait in the bus)

    def on_setpoints(self, msg: SetpointBatch, channel: str) -> None:
        """Queue setpoints that arrived on `channel`'s command channel on the bus - only the open stream's owner's,
        exactly continuing it (the core refuses the rest and counts them; the first refusal per second is logged
        with the sender).
        """
        if self.rig is None or not self.active:   # only an active driver moves the rig
            return
        if channel == getattr(self.rig.driver.stream, 'owner', None) and self.auth.refuse(
                self, msg, SETPOINT_STREAM, topics.setpoint_stream_topic(self.get_name(), channel)):
            self.rig.driver.refuse(len(msg.displacement), self.auth.verifier.last_refusal.describe())
            return   # unsigned/forged/replayed on the owner's channel: counted (other channels: the gate's to refuse)
        verdict = self.gate.offer(channel, msg.source, msg.first_sequence, conv.as_array(msg.displacement),
                                  msg.stream_id, msg.end_of_stream)
        if verdict.action == 'mute':
            self.channels.mute(channel)
        elif verdict.action == 'refused':
            self.get_logger().warning(f'setpoints from {msg.source or "an unnamed sender"} refused: {verdict.why}',
                                      throttle_duration_sec=1.0)
        self.log_events()

    def poll(self) -> None:
        """Move every sample the bus delivered into batches of at least ``batch_size`` samples. Blocks from the
        core are never split: the stamp of a batch is the real bus time of its first sample.
        """
        driver = self.rig.driver if self.rig is not None else None
        while driver is not None:
            block = driver.poll()
            if block is None:
                break
            for batch in self.batcher.add(block, self.params.samples_per_batch(self.config.sample_rate)):
                self._publish_batch(batch)
        self._publish_batch(self.batcher.due(self.params.max_batch_delay))   # the stream paused: what waits goes now
        if driver is None:
            return
        self.log_events(driver)
        status = driver.status
        key = (status.state, status.faults, status.extra['stream_id'], status.extra['last_event'])
        if key != self._status_key:
            self._status_key = key
            self.publish_status()   # transitions are published at once, not at the next status tick

    def _publish_batch(self, b) -> None:
        if b is not None:
            self.pub_samples.publish(self.auth.sign(conv.sample_batch_msg(
                b.first_sequence, b.t0, b.sample_period, b.displacement, b.force, b.setpoint, b.temperature,
                b.status_flags, b.frames_lost), SAMPLES))

    # -- status --------------------------------------------------------------------------------------------------
    def status_message(self) -> RigStatus:
        now = self.get_clock().now().nanoseconds * 1e-9
        snapshot = {'state': RigStatus.STATE_UNCONFIGURED} if self.rig is None else self.rig.driver.status
        if self.config is not None:
            limits, rate = self.config.limits, self.config.sample_rate
        else:   # parameters that make no configuration (configure says why): what they ask for
            limits, rate = asked_limits(self), self.get_parameter('sample_rate').value
        return conv.status_msg(snapshot, limits, rate, now)

    def publish_status(self) -> None:
        self.watch_owner()
        self._last_status = self.status_message()
        self.pub_status.publish(self._last_status)
        status = self._last_status
        if self.owner_silence.update(status.stream_owner, status.state, status.faults):
            self.publish_diagnostics()    # news (a fault, the owner silent or beating again): /diagnostics at once

    def watch_owner(self) -> None:
        """A stream owner that beat and then went silent for owner_timeout (OwnerWatch) loses its stream (the
        beats are read here, on the status tick: they wake the node no more).
        """
        self.owner_watch.peers.read()
        grant = self.rig.driver.stream if self.rig is not None and self.active else None
        if grant is None or not grant.owner:
            return
        why = self.owner_watch.lost(grant, self.params.owner_timeout)
        if why and self.rig.driver.owner_lost(why):
            self.log_events()

    def publish_diagnostics(self) -> None:
        status = self._last_status or self.status_message()
        backend = self.config.backend if self.config is not None else self.get_parameter('backend').value
        channel = self.config.channel if self.config is not None else self.get_parameter('can.channel').value
        hw = f'{backend}:{channel or self.get_fully_qualified_name()}'
        extra = {'parameter_changes_refused': self.refused_weakening}
        if self.rig is not None:
            extra.update(conv.bus_lines(self.rig.driver, self.config.frame_profile))
        msg = annotate_owner_silence(conv.diagnostics_msg(status, hw, extra, name=self.get_fully_qualified_name()),
                                     self.owner_silence)
        annotate(msg.status[0], self.auth)     # refused commands, named with their channel
        self.pub_diag.publish(msg)

    # -- parameters at run time -------------------------------------------------------------------------------
    def on_set_parameters(self, params) -> SetParametersResult:
        """Limits and stream settings apply at once (tighter limits: the rig ramps into them if it must); everything
        else needs configure, so it is refused while the rig is configured, with the reason (rig.live.review_change).
        """
        changed = {p.name: p.value for p in params}
        stream_open = self.rig is not None and bool(self.rig.driver.status.extra.get('stream_owner'))
        verdict = review_change(changed, protective_values(self), self.params.configured_protection, stream_open,
                                self.rig is not None, self.config, LIVE_PARAMETERS)
        if verdict.weakening:
            self.refused_weakening += 1
            self.get_logger().warning(f'parameter change refused: {verdict.why}')
        if verdict.why:
            return SetParametersResult(successful=False, reason=verdict.why)
        self.params.apply(changed)
        if self.rig is not None:   # a new batch size: the receiving thread wakes the node once per new batch
            self.rig.driver.io.wake_after(self.params.samples_per_batch(self.config.sample_rate))
        self.owner_watch.peers.silent_after = self.params.owner_timeout
        if verdict.limits is not None:
            if self.rig is not None:
                self.rig.driver.set_limits(verdict.limits)
                self.log_events()
            self.publish_status()
        return SetParametersResult(successful=True)

    def on_reset(self, request, response):
        if self.rig is None:
            response.success, response.message = False, 'rig not configured'
        else:
            why = self.rig.driver.reset()
            response.success, response.message = not why, why or 'faults cleared'
            self.log_events()
            self.publish_status()
        return response

    def on_abort(self, request, response):
        if self.rig is None:
            response.success, response.message = False, 'rig not configured'
        else:
            self.rig.driver.abort('operator abort (rig_driver/abort)')
            self.log_events()
            self.publish_status()
            response.success, response.message = True, 'safe ramp to rest'
        return response

    def log_events(self, driver=None) -> None:
        driver = driver or (self.rig.driver if self.rig is not None else None)
        if driver is None:
            return
        log = self.get_logger()
        for level, text in driver.take_events():
            # one call site per severity: rclpy refuses a call site whose severity changes
            if level == 'error':
                log.error(text)
            elif level == 'warn':
                log.warning(text)
            else:
                log.info(text)


def main(args=None):
    spin_node(with_process_nice(RigDriverNode), args)   # a process of its own: its niceness from parameter nice


if __name__ == '__main__':
    main()
