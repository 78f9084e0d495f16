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

"""recorder node: records the suite's topics to MCAP (rosbag2 MCAP layout) through the ROS-free core.

Thin by design: topic discovery, QoS matching, the control service and diagnostics live here; writing,
splitting, snapshots and loss accounting are rubber_rig.recording.Recorder's.

- Subscriptions are raw (the CDR bytes DDS delivered are written as they are: no re-encoding), with
  the reliability/durability the publishers offer (all reliable -> reliable, all transient-local ->
  transient-local, as rosbag2 adapts its requests), and a deep history.
- Topics: the ``topics`` parameter (relative names resolve in the node's namespace), or, if empty,
  every topic under the node's namespace; discovery repeats every ``discovery_period`` seconds.
- ``~/control`` (msg_defs/srv/RecorderControl, signed): START [path], STOP, SPLIT, SNAPSHOT [path]. Sample and
  setpoint batches without the rig key's signature are refused, never written (``messages_refused``; nodes/auth.py).
- ``recorder_status`` (msg_defs/msg/RecorderStatus, latched): IDLE / RECORDING / ERROR with the file, the
  error, the topics subscribed and matched with a publisher, messages written and samples known lost;
  published at once on a change of state, file, error, topics or loss (a failed write is reported by the
  callback that saw it), and at least every ``status_period``. RECORDING is only reported after the file
  was created and its header written: the directory is known writable. Programs that must be recorded
  wait for it (excitation ``require_recording``) and are aborted when it turns to ERROR.
- Failures never take the node down: an output directory that cannot be created or written, a full
  disk or any other write error turns the status to ERROR with a message naming the path, the file is
  kept readable up to its last complete chunk, and a later START (``~/control``) tries again.
- ``/diagnostics``: status named after the node's fully qualified name (``/rig1/recorder: recording``),
  hardware_id the absolute output directory; WARN only for real loss (not for sequence jumps between
  programs), ERROR when the recording stopped on an error.
"""
import importlib
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from std_msgs.msg import String

from msg_defs.msg import RecorderStatus, RigSampleBatch, SetpointBatch
from msg_defs.srv import RecorderControl
from rubber_rig.nodes import topics
from rubber_rig.nodes.auth import RECORDER_CONTROL, SAMPLES, SETPOINTS, annotate, declare_auth
from rubber_rig.nodes.draining import create_draining_subscription, take_queued
from rubber_rig.nodes.heartbeat import PERIOD, start_heartbeat
from rubber_rig.nodes.params import declare
from rubber_rig.nodes.spin import spin_node
from rubber_rig.nodes.ticks import NodeTicks
from rubber_rig.recording import Recorder, RecordingError, full_definition
from rubber_rig.recording.metadata import BOOKKEEPING_TOPIC, bookkeeping_text, bookkeeping_topic
from rubber_rig.recording.qos import offered_qos
from rubber_rig.recording.selection import in_arrival_order, recorded_publishers, recorded_topics, subscription_qos
from rubber_rig.recording.status_cadence import StatusCadence

UNSUPPORTED_SEQUENCE = 2**63   # RMW_MESSAGE_INFO_SEQUENCE_NUMBER_UNSUPPORTED is UINT64_MAX
# types whose messages are recorded only with a valid signature of the rig's key (nodes/auth.py)
SIGNED_TYPES = {'msg_defs/msg/RigSampleBatch': (SAMPLES, RigSampleBatch),
                'msg_defs/msg/SetpointBatch': (SETPOINTS, SetpointBatch)}
METADATA_FIELDS = {  # parameter metadata.<name> -> description (all strings; YAML/JSON where structured)
    'specimen': 'specimen id / description',
    'temperature': 'specimen temperature [degC] as text (e.g. "23.0")',
    'model': 'element model name (e.g. fractional_zener_berg)',
    'model_parameters': 'model parameters (YAML or JSON, SI units)',
    'test_program': 'test program (YAML)',
    'rig_configuration': 'rig configuration (YAML or JSON)',
    'operator': 'who ran the test',
    'notes': 'free text',
}


def message_class(type_name: str):
    """'pkg/msg/Type' -> the rosidl-generated class (needed to create a raw subscription)."""
    pkg, sub, name = type_name.split('/')
    return getattr(importlib.import_module(f'{pkg}.{sub}'), name)


class RecorderNode(Node):

    events_executor_refuses = 'raw subscriptions (it writes the bytes it receives)'   # nodes.executor_choice

    def __init__(self, **kwargs):
        super().__init__('recorder', **kwargs)
        self.auth = declare_auth(self)     # samples and setpoints recorded only when signed; control requests too
        self.output_dir = declare(self, 'output_dir', 'recordings', 'directory for recordings')
        self.declare_parameter('topics', Parameter.Type.STRING_ARRAY, ParameterDescriptor(
            description='topics to record (relative names resolve in the namespace); '
                        'not set or empty: every topic under the node namespace that nodes of this namespace '
                        'publish'))
        autostart = declare(self, 'autostart', True, 'start recording at once')
        split_size = declare(self, 'split_size', 0.0, 'start a new file at this size (0: never)',
                             range=(0.0, 1e6), units='MB')
        split_duration = declare(self, 'split_duration', 0.0, 'start a new file after this long (0: never)',
                                 range=(0.0, 1e7), units='s')
        compression = declare(self, 'compression', 'zstd', 'chunk compression',
                              choices=('zstd', 'lz4', 'none'))
        snapshot_duration = declare(self, 'snapshot_duration', 0.0,
                                    'keep the last N seconds in memory for SNAPSHOT (0: off)',
                                    range=(0.0, 3600.0), units='s')
        chunk_size = declare(self, 'chunk_size', 1024, 'MCAP chunk size', range=(16, 65536), units='KiB')
        flush_period = declare(self, 'flush_period', 0.25,
                               'close the chunk in progress at least this often (data at risk on a crash)',
                               range=(0.05, 60.0), units='s')
        discovery_period = declare(self, 'discovery_period', 0.25, 'look for new topics this often',
                                   range=(0.05, 60.0), units='s')
        read_period = declare(self, 'read_period', 0.05,
                              'read what arrived on the recorded topics this often: one wake-up for all of them, '
                              'not one per message (each keeps its arrival time); history_depth must hold what '
                              'arrives in this time', range=(0.001, 1.0), units='s')
        self.status_period = declare(self, 'status_period', 0.5,
                                     'publish recorder_status at least this often (and on every change)',
                                     range=(0.05, 10.0), units='s')
        diagnostics_period = declare(self, 'diagnostics_period', 1.0, 'publish /diagnostics this often',
                                     range=(0.1, 60.0), units='s')
        self.include_hidden = declare(self, 'include_hidden_topics', False,
                                      'also record hidden topics (a name part starting with _, e.g. actions)')
        self.history_depth = declare(self, 'history_depth', 1000, 'subscription history depth',
                                     range=(1, 100000))
        metadata = {name: declare(self, f'metadata.{name}', '', text) for name, text in METADATA_FIELDS.items()}
        metadata = {k: v for k, v in metadata.items() if v}
        metadata.update(node=self.get_fully_qualified_name(), namespace=self.get_namespace())
        self.core = Recorder(self.output_dir, metadata=metadata, compression=compression,
                             split_size_bytes=int(split_size * 1e6), split_duration_s=split_duration,
                             chunk_size=chunk_size * 1024, flush_interval_s=flush_period,
                             snapshot_duration_s=snapshot_duration,
                             bookkeeping_topic=bookkeeping_topic(self.get_namespace()))
        # each closed file's bookkeeping, latched (and written into the file as the same message by the core)
        self._bookkeeping_pub = self.create_publisher(String, BOOKKEEPING_TOPIC, topics.LATCHED_QOS)
        self._subs = {}                       # topic -> (subscription, type, what writes one of its messages)
        self._unrecordable = {}               # topic -> reason
        self._diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self._status_pub = self.create_publisher(RecorderStatus, topics.RECORDER_STATUS, topics.LATCHED_QOS)
        self.status_cadence = StatusCadence(self.status_period)   # on a change, and at least every status_period
        self._callback_errors = 0
        self.create_service(RecorderControl, '~/control', self._on_control)
        beat = start_heartbeat(self, lambda: 'recording' if self.core.recording else 'error' if self.core.error
                               else 'idle', timer=False)
        self.ticks = NodeTicks(self, {   # one timer for all of them (nodes/ticks.py)
            'read': (read_period, self._guarded(self.read_topics)),
            'status': (min(0.1, self.status_period), self._guarded(self.update_status)), 'heartbeat': (PERIOD, beat),
            'discover': (discovery_period, self._guarded(self.discover)),
            'flush': (flush_period, self._guarded(self.flush)),
            'diagnostics': (diagnostics_period, self._guarded(self.publish_diagnostics))})
        self._reported_error = None
        if autostart:
            self.start_recording()
        self._guarded(self.discover)()
        self.update_status()

    def _guarded(self, fn):
        """A timer callback that logs instead of raising: no exception may take the node down."""
        def call():
            try:
                fn()
            except Exception as exc:  # noqa: BLE001 - reported, counted, the node keeps running
                self._callback_errors += 1
                self.get_logger().error(f'{getattr(fn, "__name__", "callback")} failed: '
                                        f'{type(exc).__name__}: {exc}', throttle_duration_sec=5.0)
        return call

    def start_recording(self, path=None):
        """Start (or keep) recording; returns the file, or None on failure (then the status is ERROR with
        the reason naming the path, and the reason is logged once, without a traceback).
        """
        try:
            file = self.core.start(path)
        except (RecordingError, OSError) as exc:   # unwritable / uncreatable directory, disk full
            if self.core.error is None or self.core.recording:
                self.core.error = RecordingError(str(exc))
            self.get_logger().error(f'not recording: {self.core.error}')
            self.update_status()
            return None
        self.get_logger().info(f'recording to {file}')
        self.update_status()
        return file

    def flush(self):
        self.core.flush()
        if self.core.error is not None:
            self.update_status()

    # -- topics ------------------------------------------------------------------------------
    def configured_topics(self) -> list[str]:
        try:
            return [t for t in (self.get_parameter('topics').value or []) if t]
        except ParameterUninitializedException:   # declared without a value: record everything
            return []

    def wanted_topics(self, graph):
        """The (topic, types) of ``graph`` to record (recording.selection)."""
        return recorded_topics(graph, self.get_namespace(), [self.resolve_topic_name(t) for t in
                                                             self.configured_topics()], self.include_hidden)

    def discover(self):
        for name, types in self.wanted_topics(self.get_topic_names_and_types()):
            if name in self._subs or name in self._unrecordable:
                continue
            publishers = recorded_publishers(self.get_publishers_info_by_topic(name),
                                             (self.get_name(), self.get_namespace()), self.get_namespace(),
                                             bool(self.configured_topics()))
            if not publishers:
                continue                      # QoS is matched to publishers: wait for one
            type_name = types[0]
            try:
                cls = message_class(type_name)
                full_definition(type_name)        # the schema must be writable before we subscribe
            except (ImportError, AttributeError, ValueError) as exc:
                self._unrecordable[name] = f'type {type_name} cannot be recorded: {exc}'
                self.get_logger().error(f'cannot record {name}: {self._unrecordable[name]}')
                continue
            offered = [offered_qos(p) for p in publishers]
            reliable, latched, depth = subscription_qos(offered, self.history_depth)
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                             reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
            self.core.set_qos(name, offered)
            write = self._callback(name, type_name)
            sub = create_draining_subscription(self, cls, name, write, qos, raw=True, polled=True)
            self._subs[name] = (sub, type_name, write)
            self.get_logger().info(f'recording {name} [{type_name}] '
                                   f'({"reliable" if reliable else "best effort"}'
                                   f'{", transient local" if latched else ""})')

    def read_topics(self) -> None:
        """Write what arrived on every recorded topic since the last read, in the order it arrived (the topics'
        messages interleaved by their receive time, as a recorder woken per message would have written them).
        """
        for write, (data, info) in in_arrival_order((write, take_queued(sub)) for sub, _, write in self._subs.values()):
            write(data, info)

    def _callback(self, topic, type_name):
        write, clock = self.core.write, self.get_clock()
        signed = SIGNED_TYPES.get(type_name)     # (purpose, class) of a type whose messages must verify

        def on_message(data, info):
            try:
                if signed is not None and self.auth.refuse(self, deserialize_message(data, signed[1]), signed[0],
                                                           topic):
                    self.core.refuse(topic)      # a forgery never enters a recording: counted, named, not written
                    return
                log_ns = info.get('received_timestamp') or clock.now().nanoseconds
                seq = info.get('publication_sequence_number')
                if seq is None or seq >= UNSUPPORTED_SEQUENCE:   # rmw without sequence numbers
                    seq = None                                    # -> the core counts per channel
                if not write(topic, type_name, data, log_ns, info.get('source_timestamp') or log_ns, seq) \
                        and self.core.error is not None and self.status_cadence.key is not None \
                        and self.status_cadence.key[0] != RecorderStatus.STATE_ERROR:
                    self.update_status()                          # ERROR at once, not at the next tick
            except Exception as exc:  # noqa: BLE001 - a bad message must not take the recorder down
                self._callback_errors += 1
                self.get_logger().error(f'recording a message on {topic} failed: {type(exc).__name__}: {exc}',
                                        throttle_duration_sec=5.0)
        return on_message

    # -- control -----------------------------------------------------------------------------
    def _on_control(self, request, response):
        cmd = request.command
        try:
            if self.auth.refuse(self, request, RECORDER_CONTROL, f'{self.get_fully_qualified_name()}/control'):
                raise RecordingError(f'refused: {self.auth.verifier.last_refusal.why}')
            if cmd == RecorderControl.Request.START:
                response.file = str(self.start_recording(request.path or None) or '')
                if not self.core.recording:
                    raise RecordingError(str(self.core.error or 'not recording'))
                response.message = 'recording'
            elif cmd == RecorderControl.Request.STOP:
                files = self.core.stop()
                self.publish_bookkeeping()
                response.file = str(files[-1]) if files else ''
                response.message = f'stopped; {len(files)} file(s)'
            elif cmd == RecorderControl.Request.SPLIT:
                response.file = str(self.core.split())
                self.publish_bookkeeping()
                response.message = 'split'
            elif cmd == RecorderControl.Request.SNAPSHOT:
                response.file = str(self.core.snapshot(request.path or None))
                response.message = 'snapshot written'
            else:
                raise RecordingError(f'unknown command {cmd} (START=0, STOP=1, SPLIT=2, SNAPSHOT=3)')
            response.success = True
        except Exception as exc:  # noqa: BLE001 - refused with the reason, the node keeps running
            response.success, response.message = False, str(exc) or type(exc).__name__
        if not response.file and self.core.files:
            response.file = str(self.core.files[-1])
        self.get_logger().info(f'control {cmd}: {response.message}')
        self.update_status()
        return response

    # -- status ------------------------------------------------------------------------------
    def subscribed_topics(self) -> list:
        """(fully qualified topic, matched publishers) of the subscriptions matched with at least one publisher."""
        out = []
        for name, (sub, _, _) in sorted(self._subs.items()):
            try:
                count = sub.get_publisher_count()
            except Exception:  # noqa: BLE001 - a subscription being destroyed
                continue
            if count > 0:
                out.append((name, count))
        return out

    def status_message(self) -> RecorderStatus:
        core = self.core
        if core.recording:
            state, name = RecorderStatus.STATE_RECORDING, 'recording'
        elif core.error is not None:
            state, name = RecorderStatus.STATE_ERROR, 'error'
        else:
            state, name = RecorderStatus.STATE_IDLE, 'idle'
        path = core.current_file or (core.files[-1] if core.files else '')
        stats_written = core.messages_written + (core.writer.messages_written if core.writer else 0)
        matched = self.subscribed_topics()
        msg = RecorderStatus(state=state, state_name=name, path=str(path),
                             error=str(core.error) if core.error is not None and not core.recording else '',
                             topics=[name for name, _ in matched], topic_publishers=[n for _, n in matched],
                             messages_written=int(stats_written),
                             samples_lost=int(core.samples_lost_total))
        msg.header.stamp = self.get_clock().now().to_msg()
        return msg

    def update_status(self, force: bool = False) -> None:
        """Publish recorder_status if anything but the counters changed, or status_period passed."""
        msg = self.status_message()
        key = (msg.state, msg.path, msg.error, tuple(msg.topics), tuple(msg.topic_publishers), msg.samples_lost)
        said = self.status_cadence.key or (None,) * 3
        if not self.status_cadence.due(key, self.get_clock().now().nanoseconds * 1e-9, force):
            return
        if key[:3] != said[:3] and msg.state == RecorderStatus.STATE_ERROR:
            self.get_logger().error(f'recorder status: error: {msg.error}')
        self._status_pub.publish(msg)

    # -- diagnostics -------------------------------------------------------------------------
    def publish_diagnostics(self):
        stats = self.core.stats()
        stats['topics'] = len(self._subs)
        stats['unrecordable_topics'] = ', '.join(sorted(self._unrecordable))
        stats['callback_errors'] = self._callback_errors
        d = DiagnosticStatus(name=f'{self.get_fully_qualified_name()}: recording',
                             hardware_id=str(Path(self.output_dir).absolute()))
        if stats['error']:
            d.level, d.message = DiagnosticStatus.ERROR, 'stopped: ' + stats['error']
            if self._reported_error != stats['error']:
                self._reported_error = stats['error']
                self.get_logger().error(stats['error'])
        elif stats['messages_dropped'] or stats['samples_lost_total'] or self._unrecordable:
            d.level = DiagnosticStatus.WARN
            d.message = (f'{stats["messages_dropped"]} messages not recorded, '
                         f'{stats["samples_lost_total"]} samples lost ({stats["sequence_gaps"]} gaps)')
        else:
            d.level = DiagnosticStatus.OK
            d.message = 'recording' if stats['recording'] else 'idle'
        d.values = [KeyValue(key=k, value=str(v)) for k, v in stats.items()]
        annotate(d, self.auth)     # forged samples and control requests refused: how many, from where
        arr = DiagnosticArray(status=[d])
        arr.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(arr)

    def publish_bookkeeping(self) -> None:
        """The last closed file's records (the ``rubber_rig`` and ``rubber_rig.close`` metadata) on the latched
        ``recording_info`` topic, as JSON: what a tool that drops MCAP metadata still shows.
        """
        if self.core.reports:
            self._bookkeeping_pub.publish(String(data=bookkeeping_text(self.core.metadata, self.core.reports[-1])))

    def destroy_node(self):
        was_recording = self.core.recording
        try:
            files = self.core.stop()
        except Exception as exc:  # noqa: BLE001 - shutting down: say so, do not raise
            files = list(self.core.files)
            self.get_logger().error(f'closing the recording failed: {exc}')
        if was_recording and files:
            self.get_logger().info(f'closed {len(files)} file(s), last {files[-1]}')
        return super().destroy_node()


def main(args=None):
    spin_node(RecorderNode, args)


if __name__ == '__main__':
    main()
