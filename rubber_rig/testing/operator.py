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

"""An operator node that drives the suite from outside through its ROS interfaces only (topics, services, the
action) and keeps what it saw (samples, statuses, predictions, setpoints). Waits are bounded waits on conditions,
never fixed sleeps. The suite's processes: :mod:`.processes`.
"""
from __future__ import annotations

import threading
import time
import uuid
from typing import Callable

import numpy as np
import rclpy
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient
from rclpy.action.client import ClientGoalHandle
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_srvs.srv import Trigger

from msg_defs.action import RunProgram
from msg_defs.msg import (
    CycleMetrics,
    DetectorEvent,
    ModelPrediction,
    RecorderStatus,
    RigSampleBatch,
    RigStatus,
    SetpointBatch,
)
from msg_defs.srv import HoldProgram

from ..dds import configure_dds
from ..nodes import conversions as conv
from ..nodes import topics
from ..nodes.auth import RUN_PROGRAM, SERVICE_PURPOSES, client_auth


def new_goal_id():
    """A fresh action goal id (unique_identifier_msgs/UUID, taken from the action's own request type)."""
    goal_id = RunProgram.Impl.SendGoalService.Request().goal_id
    goal_id.uuid = list(uuid.uuid4().bytes)
    return goal_id


class Operator:
    """A node in this process that drives a suite from outside: the action, the services, a foreign setpoint
    publisher, and everything the rig publishes (applied command, status, recorder status) collected.

    Runs its own rclpy context and executor thread; use as a context manager.
    """

    RETRY = 2.0      # [s] an unanswered goal or service request is sent again after this long

    def __init__(self, namespace: str, domain_id: int, name: str = 'operator', key_file: str | None = None,
                 signs: bool = True):
        self.ns = namespace.rstrip('/')
        self.context = Context()
        configure_dds()
        rclpy.init(args=[], context=self.context, domain_id=int(domain_id),
                   signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node(name, namespace=namespace, context=self.context)
        # the rig's operator signs its goals and requests with the rig's key (RUBBER_RIG_KEY_FILE, or `key_file`);
        # signs=False: a stranger without the key (or with another key file: a stranger with the wrong key)
        self.auth = client_auth(self.node.get_fully_qualified_name(), key_file) if signs else None
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.lock = threading.Lock()
        self.batches: list[RigSampleBatch] = []
        self.statuses: list[tuple[float, RigStatus]] = []
        self.status: RigStatus | None = None
        self.recorder: RecorderStatus | None = None
        self.setpoints_seen: list[SetpointBatch] = []
        self.events: list[DetectorEvent] = []
        self.cycle_metrics: list[CycleMetrics] = []
        self.predicted_until = -1          # sequence after the latest sample element_model predicted
        n = self.node
        n.create_subscription(ModelPrediction, topics.PREDICTION, self._on_prediction, topics.STREAM_QOS)
        n.create_subscription(CycleMetrics, topics.CYCLE_METRICS, self.cycle_metrics.append, topics.EVENT_QOS)
        n.create_subscription(DetectorEvent, topics.EVENTS, self.events.append, topics.EVENT_QOS)
        n.create_subscription(RigSampleBatch, topics.SAMPLES, self._on_samples, topics.STREAM_QOS)
        n.create_subscription(RigStatus, topics.STATUS, self._on_status, topics.LATCHED_QOS)
        n.create_subscription(RecorderStatus, topics.RECORDER_STATUS, self._on_recorder, topics.LATCHED_QOS)
        n.create_subscription(SetpointBatch, topics.SETPOINTS, self._on_setpoints, topics.STREAM_QOS)
        self.pub_setpoints = {   # the public topic everyone watches, the driver's command channel
            'setpoints': n.create_publisher(SetpointBatch, topics.SETPOINTS, topics.STREAM_QOS),
            'command': n.create_publisher(
                SetpointBatch, topics.setpoint_stream_topic('rig_driver', n.get_fully_qualified_name()),
                topics.STREAM_QOS)}
        self.action = ActionClient(n, RunProgram, 'run_program', **topics.ACTION_SERVICES_QOS)
        self._clients = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name='operator', daemon=True)
        self._thread.start()

    def _spin(self):
        while not self._stop.is_set() and self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:   # noqa: BLE001 - shutting down
                if self._stop.is_set():
                    return
                raise

    def close(self):
        self._stop.set()
        self._thread.join(timeout=5)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- inputs
    def _on_samples(self, msg):
        with self.lock:
            self.batches.append(msg)

    def _on_status(self, msg):
        with self.lock:
            self.status = msg
            self.statuses.append((time.monotonic(), msg))

    def _on_prediction(self, msg):
        self.predicted_until = msg.first_sequence + len(msg.predicted_force)

    def _on_recorder(self, msg):
        self.recorder = msg

    def _on_setpoints(self, msg):
        with self.lock:
            self.setpoints_seen.append(msg)

    def clear_history(self):
        """Forget the samples and setpoints received so far (a restarted rig numbers its samples from 0)."""
        with self.lock:
            self.batches.clear()
            self.setpoints_seen.clear()

    def first_departure(self, since: int, tolerance: float = 1e-6):
        """The first sample (sequence >= since) whose applied command is not the setpoint streamed for it (by
        more than `tolerance` [m]): where a ramp or hold took over from the program. Returns (sequence, wall
        time of the sample [s, time.time() clock: its frame's bus timestamp]) or None.
        """
        with self.lock:
            sp = [(b.first_sequence, conv.as_array(b.displacement)) for b in self.setpoints_seen
                  if b.first_sequence + len(b.displacement) > since]
            bs = [b for b in self.batches if b.first_sequence + len(b.setpoint) > since]
        queued = {}
        for first, x in sp:
            for i, v in enumerate(x.tolist()):
                queued[first + i] = v
        for b in sorted(bs, key=lambda b: b.first_sequence):
            t0 = b.header.stamp.sec + b.header.stamp.nanosec * 1e-9
            for i, u in enumerate(conv.as_array(b.setpoint).tolist()):
                seq = b.first_sequence + i
                if seq >= since and (seq not in queued or abs(u - queued[seq]) > tolerance):
                    return seq, t0 + i * b.sample_period
        return None

    def applied(self, since: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(sequence, applied command [m], measured displacement [m]) of every sample received (sequence >= since),
        sorted by sequence.
        """
        with self.lock:
            bs = [b for b in self.batches if b.first_sequence + len(b.setpoint) > since]
        if not bs:
            return np.empty(0, dtype=np.int64), np.empty(0), np.empty(0)
        seq = np.concatenate([b.first_sequence + np.arange(len(b.setpoint)) for b in bs])
        u = np.concatenate([conv.as_array(b.setpoint) for b in bs])
        x = np.concatenate([conv.as_array(b.displacement) for b in bs])
        order = np.argsort(seq, kind='stable')
        keep = seq[order] >= since
        return seq[order][keep], u[order][keep], x[order][keep]

    @property
    def last_sequence(self) -> int:
        with self.lock:
            if not self.batches:
                return -1
            b = self.batches[-1]
            return b.first_sequence + len(b.setpoint) - 1

    # -- waiting
    @staticmethod
    def wait_for(condition: Callable[[], bool], timeout: float, period: float = 0.01) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if condition():
                return True
            time.sleep(period)
        return bool(condition())

    def wait_status(self, condition: Callable[[RigStatus], bool], timeout: float) -> bool:
        return self.wait_for(lambda: self.status is not None and condition(self.status), timeout)

    def wait_ready(self, timeout: float = 30.0) -> bool:
        """The driver is active and idle (or holding) with no stream, and the excitation answers."""
        ok = self.wait_status(lambda s: s.state in (RigStatus.STATE_IDLE, RigStatus.STATE_HOLDING)
                              and not s.stream_owner, timeout)
        return ok and self.action.wait_for_server(timeout_sec=timeout)

    # -- the action
    def send_goal(self, program_yaml: str = '', program_path: str = '', amplitude_control: bool = False,
                  timeout: float = 10.0, action: str = 'run_program'):
        """Send a goal to the RunProgram action `action` (default: this namespace's run_program); returns the
        goal handle (accepted or not) or None if nothing answered.
        """
        deadline = time.monotonic() + timeout
        client = self.action
        if action != 'run_program':
            client = self._clients.get(('action', action))
            if client is None:
                client = ActionClient(self.node, RunProgram, action, **topics.ACTION_SERVICES_QOS)
                self._clients[('action', action)] = client
        if not client.wait_for_server(timeout_sec=timeout):
            return None
        goal = RunProgram.Goal(program_yaml=program_yaml, program_path=program_path,
                               amplitude_control=amplitude_control)
        # A request sent before DDS matched a just (re)started server is lost (services are volatile), and the
        # graph still lists a killed server until its lease expires: resend until one answers. The answer can be
        # lost too while the server runs the goal (a restarted server that has not matched our response reader
        # yet: "failed to send response (timeout)"), so every resend carries the same goal id: a server that
        # has the goal rejects the duplicate, and we take up the goal it runs instead of reading a refusal.
        goal_id = new_goal_id()
        resent = False
        while True:
            fut = client.send_goal_async(self.sign(goal, RUN_PROGRAM), goal_uuid=goal_id)   # each send signed anew
            if self.wait_for(fut.done, min(self.RETRY, max(0.0, deadline - time.monotonic()))):
                response = fut.result()
                if response.accepted or not resent:
                    return response
                return self._known_goal(client, goal_id) or response
            resent = True
            if time.monotonic() >= deadline:
                return None

    def _known_goal(self, client, goal_id):
        """The handle of goal `goal_id` if the server has it (its result is not STATUS_UNKNOWN within 1 s:
        running, or ended), else None.
        """
        handle = ClientGoalHandle(client, goal_id, RunProgram.Impl.SendGoalService.Response(accepted=True))
        fut = handle.get_result_async()
        if self.wait_for(fut.done, 1.0) and fut.result().status == GoalStatus.STATUS_UNKNOWN:
            return None
        return handle

    def result(self, handle, timeout: float):
        """The goal's result (RunProgram.Result) or None if it did not end within `timeout` seconds."""
        fut = handle.get_result_async()
        return fut.result().result if self.wait_for(fut.done, timeout) else None

    def run(self, program_yaml: str, timeout: float = 60.0, **kwargs):
        handle = self.send_goal(program_yaml, **kwargs)
        assert handle is not None and handle.accepted, 'run_program goal not accepted'
        return self.result(handle, timeout)

    def cancel(self, handle, timeout: float = 5.0) -> bool:
        fut = handle.cancel_goal_async()
        return self.wait_for(fut.done, timeout)

    # -- services
    def call(self, service: str, srv_type, request=None, timeout: float = 5.0):
        """Call `service` (relative names resolve in the namespace); None if it did not answer in time."""
        client = self._clients.get(service)
        if client is None:
            client = self._clients[service] = self.node.create_client(srv_type, service)
        deadline = time.monotonic() + timeout
        if not client.wait_for_service(timeout_sec=timeout):
            return None
        while True:   # resend a lost request, as send_goal does
            request = request if request is not None else srv_type.Request()
            if hasattr(request, 'signature'):    # signed anew for each attempt: a resend is not a replay
                self.sign(request, SERVICE_PURPOSES.get(service.rsplit('/', 1)[-1], ''))
            fut = client.call_async(request)
            if self.wait_for(fut.done, min(self.RETRY, max(0.0, deadline - time.monotonic()))):
                return fut.result()
            if time.monotonic() >= deadline:
                return None

    def sign(self, msg, purpose: str):
        """`msg` signed for `purpose` with the operator's key (unchanged for a stranger: signs=False)."""
        return self.auth.sign(msg, purpose) if self.auth is not None else msg

    def trigger(self, service: str, timeout: float = 5.0):
        return self.call(service, Trigger, Trigger.Request(), timeout)

    def hold(self, on: bool, timeout: float = 5.0):
        return self.call('excitation/hold', HoldProgram, HoldProgram.Request(data=on), timeout)

    def publish_setpoints(self, first_sequence: int, x, stream_id: int = 0, source: str = '/intruder',
                          block_index: int = 0, sample_period: float = 1e-3, topic: str = 'command'):
        """Publish a batch as an intruder would: on the driver's command channel or on ``setpoints``."""
        self.pub_setpoints[topic].publish(conv.setpoint_batch_msg(first_sequence, sample_period, x, block_index,
                                                                  stream_id=stream_id, source=source))
