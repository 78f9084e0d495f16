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

"""SuiteMonitor: a client node that watches the suite (used by ``rubber-rig bench``, the tests and the benchmark).

It subscribes to every stream with the suite's QoS, counts sequence gaps per stream (the loss accounting of
the benchmark), measures the latency from a sample being taken (its stamp) to the prediction for it arriving
here, and wraps the two clients the main job needs: the excitation's ``run_program`` action and the recorder's
``~/control`` service. Callbacks only append to lists/counters; readers in other threads take snapshots.
"""
from __future__ import annotations

from collections import defaultdict
from typing import Callable

import numpy as np
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import String
from std_srvs.srv import Trigger

from msg_defs.action import RunProgram
from msg_defs.msg import (
    CycleMetrics,
    DetectorEvent,
    ModelParameters,
    ModelPrediction,
    RecorderStatus,
    RigSampleBatch,
    RigStatus,
    SetpointBatch,
)
from msg_defs.srv import RecorderControl
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes import topics
from rubber_rig.nodes.auth import RECORDER_CONTROL, RUN_PROGRAM, client_auth
from rubber_rig.nodes.heartbeat import Peers


class StreamStats:
    """Continuity of one batched stream: messages, samples, gaps and missing samples."""

    def __init__(self):
        self.messages = self.samples = self.gaps = self.missing = 0
        self.first = self.next = None

    def observe(self, first: int, n: int) -> None:
        if self.next is not None and first != self.next:
            self.gaps += 1
            self.missing += max(0, first - self.next)
        if self.first is None:
            self.first = first
        self.next = first + n
        self.messages += 1
        self.samples += n

    def as_dict(self) -> dict:
        return {'messages': self.messages, 'samples': self.samples, 'gaps': self.gaps, 'missing': self.missing,
                'first_sequence': self.first, 'next_sequence': self.next}


class SuiteMonitor(Node):

    def __init__(self, node_name: str = 'suite_monitor', keep_messages: bool = False, recorder: str = 'recorder',
                 excitation: str = 'excitation', **kwargs):
        super().__init__(node_name, **kwargs)
        self.keep = keep_messages
        self.messages: dict[str, list] = defaultdict(list)
        self.stats = {name: StreamStats() for name in ('samples', 'prediction', 'setpoints')}
        self.latency_last: list[float] = []     # [s] last sample of a batch taken -> its prediction here
        self.latency_first: list[float] = []    # [s] first sample of a batch taken -> its prediction here
        self.cycle_metrics: list[CycleMetrics] = []
        self.feedback: list = []
        self.events: list[DetectorEvent] = []
        self.status: RigStatus | None = None
        self.recorder_status: RecorderStatus | None = None
        self.model_parameters: ModelParameters | None = None
        self.program_yaml = ''
        self.temperature = float('nan')
        sub = self.create_subscription
        self.live = {name: sub(msg_type, name, callback, qos) for name, msg_type, callback, qos in (
            (topics.SAMPLES, RigSampleBatch, self._on_samples, topics.STREAM_QOS),
            (topics.PREDICTION, ModelPrediction, self._on_prediction, topics.STREAM_QOS),
            (topics.SETPOINTS, SetpointBatch, self._on_setpoints, topics.STREAM_QOS),
            (topics.CYCLE_METRICS, CycleMetrics, self._on_cycle, topics.EVENT_QOS),
            (topics.EVENTS, DetectorEvent, self.events.append, topics.EVENT_QOS))}
        sub(RigStatus, topics.STATUS, self._on_status, topics.LATCHED_QOS)
        sub(ModelParameters, topics.MODEL_PARAMETERS, self._on_parameters, topics.LATCHED_QOS)
        sub(String, topics.PROGRAM, self._on_program, topics.LATCHED_QOS)
        sub(RecorderStatus, topics.RECORDER_STATUS, self._on_recorder_status, topics.LATCHED_QOS)
        self.auth = client_auth(self.get_fully_qualified_name())   # the rig's key (RUBBER_RIG_KEY_FILE, --key-file)
        self.peers = Peers(self)          # the suite's heartbeats: peers.silent() names a node stuck or gone
        self.action = ActionClient(self, RunProgram, 'run_program', **topics.ACTION_SERVICES_QOS)
        self.recorder_control = self.create_client(RecorderControl, f'{recorder}/control')
        self.excitation_abort = self.create_client(Trigger, f'{excitation}/abort')

    # -- callbacks (executor thread) -------------------------------------------------------------------------
    def _on_samples(self, msg: RigSampleBatch) -> None:
        self.stats['samples'].observe(msg.first_sequence, len(msg.displacement))
        self.temperature = msg.temperature
        if self.keep:
            self.messages['samples'].append(msg)

    def _on_prediction(self, msg: ModelPrediction) -> None:
        now = self.get_clock().now().nanoseconds * 1e-9   # ROS time: system time, as the bus stamps the samples
        n = len(msg.displacement)
        self.stats['prediction'].observe(msg.first_sequence, n)
        t0 = conv.to_seconds(msg.header.stamp)
        self.latency_first.append(now - t0)
        self.latency_last.append(now - (t0 + (n - 1) * msg.sample_period))
        if self.keep:
            self.messages['prediction'].append(msg)

    def _on_setpoints(self, msg: SetpointBatch) -> None:
        self.stats['setpoints'].observe(msg.first_sequence, len(msg.displacement))
        if self.keep:
            self.messages['setpoints'].append(msg)

    def _on_cycle(self, msg: CycleMetrics) -> None:
        self.cycle_metrics.append(msg)

    def _on_status(self, msg: RigStatus) -> None:
        self.status = msg
        if self.keep:
            self.messages['status'].append(msg)

    def _on_parameters(self, msg: ModelParameters) -> None:
        self.model_parameters = msg
        if self.keep:
            self.messages['model_parameters'].append(msg)

    def _on_program(self, msg: String) -> None:
        self.program_yaml = msg.data

    def _on_recorder_status(self, msg: RecorderStatus) -> None:
        self.recorder_status = msg

    # -- clients --------------------------------------------------------------------------------------------------
    def send_program(self, program_yaml: str = '', program_path: str = '', amplitude_control: bool = True):
        """Send a RunProgram goal; returns the goal-handle future (feedback lands in ``self.feedback``)."""
        goal = RunProgram.Goal(program_path=program_path, program_yaml=program_yaml,
                               amplitude_control=amplitude_control)
        self.auth.sign(goal, RUN_PROGRAM)     # a rig takes goals only with its key's signature
        return self.on_executor(lambda: self.action.send_goal_async(
            goal, feedback_callback=lambda m: self.feedback.append(m.feedback)))

    def on_executor(self, send: Callable[[], Future]) -> Future:
        """``send()`` (a request of the action client returning its future) run on this node's executor thread;
        returns a future with that future's result.

        rclpy's ActionClient (Jazzy) records a request's sequence number only after sending it, without a lock: a
        response the executor thread takes in between is dropped ("Ignoring unexpected goal response") and the
        future never completes. The faster the executor waits (issue 37's LeanExecutor), the likelier that is, so
        requests from another thread (the bench's main thread) are sent from the executor's own thread.
        """
        result = Future()

        def chain(task: Future) -> None:
            if task.exception() is not None:
                result.set_exception(task.exception())
                return
            task.result().add_done_callback(lambda inner: result.set_result(inner.result()))

        self.executor.create_task(send).add_done_callback(chain)
        return result

    def recorder(self, command: int, path: str = ''):
        """Call the recorder's ~/control (RecorderControl.Request.START/STOP/SPLIT/SNAPSHOT); returns a future."""
        return self.recorder_control.call_async(self.auth.sign(RecorderControl.Request(command=command, path=path),
                                                               RECORDER_CONTROL))

    def unmatched(self) -> list[str]:
        """The live topics (samples, prediction, setpoints, cycle metrics, events) this monitor has no publisher for
        yet: what it would miss if a program started now. Under load DDS discovery can take seconds, and a block
        whose cycle metrics went out before the match is missing from the table.
        """
        return [self.resolve_topic_name(name) for name, s in self.live.items() if s.get_publisher_count() == 0]

    def recorder_subscribed(self, *names: str) -> bool:
        """True when the recorder node subscribes to every one of the given topics."""
        for name in names:
            infos = self.get_subscriptions_info_by_topic(self.resolve_topic_name(name))
            if not any(i.node_name == 'recorder' for i in infos):
                return False
        return True

    def recording_ready(self, *names: str) -> str:
        """'' when the recorder reports RECORDING with every given topic subscribed and matched, else why
        not (an ERROR status gives the recorder's own reason, which names the path).
        """
        st = self.recorder_status
        if st is None:
            return f"no recorder status on '{self.resolve_topic_name(topics.RECORDER_STATUS)}' yet"
        if st.state == RecorderStatus.STATE_ERROR:
            return f'recorder error: {st.error}'
        if st.state != RecorderStatus.STATE_RECORDING:
            return f'recorder is {st.state_name} (not recording)'
        missing = [n for n in (self.resolve_topic_name(n) for n in names) if n not in st.topics]
        return f"recorder not yet subscribed to {', '.join(missing)}" if missing else ''

    # -- reporting --------------------------------------------------------------------------------------------------
    def latency_summary(self) -> dict:
        out = {}
        for key, values in (('last_sample', self.latency_last), ('first_sample', self.latency_first)):
            v = np.asarray(values[:])
            if v.size:
                out[key] = {'median_ms': float(np.median(v) * 1e3), 'p99_ms': float(np.percentile(v, 99) * 1e3),
                            'max_ms': float(v.max() * 1e3), 'count': int(v.size)}
        return out
