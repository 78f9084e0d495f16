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

"""The recorder node with real rclpy + Fast DDS: RigSampleBatch published in-process, file read back."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from msg_defs.msg import RigSampleBatch, RigStatus
from msg_defs.srv import RecorderControl
from rubber_rig.cli.main import main as cli
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes import topics
from rubber_rig.nodes.auth import RECORDER_CONTROL, SAMPLES, client_auth, signed
from rubber_rig.nodes.recorder_node import RecorderNode
from rubber_rig.recording import load_recording
from rubber_rig.recording.qos import parse_offered_qos
from rubber_rig.security import init_key

from support.ros import ros_context, sample_batch, spin_until, spinning

pytestmark = pytest.mark.ros   # every test here runs nodes with real rclpy

REPO = Path(__file__).resolve().parents[1]
BATCH = 20
PERIOD = 1e-3
# A DDS domain of our own: a node another test left behind (a root-namespace rig_driver's
# /rig_driver/transition_event: `rubber-rig bench` tests run on domains 20-139, their participants stay listed for
# the 5 s lease) must not be seen by the discovery tests here. 1-10 is used by no other module (test_wakeups'
# simulated-clock test has 11-19; domain 0 is everyone's default).
DOMAIN = 1 + os.getpid() % 10


@pytest.fixture
def context():
    with ros_context(DOMAIN) as ctx:
        yield ctx


def control_caller(executor, control):
    """call(command, path='') -> RecorderControl response, spinning ``executor`` until it arrives."""
    def call(command, path=''):
        future = control.call_async(signed(RecorderControl.Request(command=command, path=path), RECORDER_CONTROL))
        assert spin_until(executor, future.done)
        return future.result()
    return call


def batch(k, skip=0, frames_lost=0):
    return sample_batch(k * BATCH + skip, BATCH, period=PERIOD, frames_lost=frames_lost,
                        temperature=23.0 + k * 0.01, status_flags=k % 3)


def test_recorder_node_records_published_batches(context, tmp_path):
    ns = '/rigtest'
    pub_node = Node('fake_rig', namespace=ns, context=context)
    rec = RecorderNode(namespace=ns, context=context, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path)),
        Parameter('autostart', value=False),
        Parameter('discovery_period', value=0.1),
        Parameter('diagnostics_period', value=0.2),
        Parameter('metadata.specimen', value='bushing B-7'),
        Parameter('metadata.temperature', value='23.0'),
    ])
    client_node = Node('client', context=context)
    with spinning(context, pub_node, rec, client_node) as executor:
        samples = pub_node.create_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
        status = pub_node.create_publisher(RigStatus, topics.STATUS, topics.LATCHED_QOS)
        status.publish(RigStatus(state=RigStatus.STATE_RUNNING, state_name='running'))
        diagnostics = []
        client_node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS,
                                        lambda m: diagnostics.append(m), 10)
        control = client_node.create_client(RecorderControl, f'{ns}/recorder/control')
        assert control.wait_for_service(timeout_sec=10)

        call = control_caller(executor, control)

        out = tmp_path / 'run1'
        response = call(RecorderControl.Request.START, str(out))
        assert response.success, response.message
        # both topics discovered and subscribed (QoS matched to the publishers) before publishing
        assert spin_until(executor, lambda: len(rec._subs) == 2)
        assert spin_until(executor, lambda: rec.core.writer.messages_by_topic.get(f'{ns}/status', 0) == 1)
        sent = 0
        for k in range(100):
            # one gap of 7 samples at batch 60, lost on the bus: the driver reports it on the next batch
            samples.publish(batch(k, skip=7 if k >= 60 else 0, frames_lost=7 if k == 60 else 0))
            sent += 1
            executor.spin_once(timeout_sec=0)
        assert spin_until(executor, lambda: rec.core.writer.messages_by_topic.get(f'{ns}/samples', 0) == sent)
        assert spin_until(executor, lambda: any(
            kv.key == 'samples_lost' and kv.value == '7' for m in diagnostics for s in m.status for kv in s.values))
        response = call(RecorderControl.Request.STOP)
        assert response.success, response.message
        files = sorted(out.glob('*.mcap'))
        assert [f.name for f in files] == ['run1_0.mcap']
        assert call(RecorderControl.Request.SPLIT).success is False     # not recording: clear refusal

    r = load_recording(files[0])
    assert len(r) == 100 * BATCH
    expected = np.concatenate([np.asarray(batch(k, 7 if k >= 60 else 0).force) for k in range(100)])
    np.testing.assert_array_equal(r.force, expected)
    assert r.sequence[0] == 0 and r.sequence[-1] == 100 * BATCH + 6
    assert r.samples_lost == 7 and len(r.gaps) == 1 and r.gaps[0]['expected'] == 60 * BATCH
    assert r.metadata['specimen'] == 'bushing B-7' and r.metadata['temperature'] == '23.0'
    assert r.closing[0]['samples_lost'] == 7 and r.closing[0]['messages_dropped'] == 0
    assert r.closing[0]['messages_by_topic'] == {f'{ns}/samples': 100, f'{ns}/status': 1}
    assert r.messages[f'{ns}/status'][0][1].state_name == 'running'
    qos = parse_offered_qos(r.topics[f'{ns}/status']['qos'])
    assert qos[0]['durability'] == 'transient_local' and qos[0]['reliability'] == 'reliable'
    # history and depth are not announced by DDS discovery: like rosbag2, only what the graph reports
    qos = parse_offered_qos(r.topics[f'{ns}/samples']['qos'])
    assert qos[0]['reliability'] == 'reliable' and qos[0]['durability'] == 'volatile'
    # log time = reception, publish time = source timestamp, sequence = DDS publication sequence number
    from mcap.reader import make_reader
    with open(files[0], 'rb') as f:
        raw = [(m.log_time, m.publish_time, m.sequence) for _, ch, m in make_reader(f).iter_messages()
               if ch.topic == f'{ns}/samples']
    assert all(0 < pub <= log < time.time_ns() for log, pub, _ in raw)
    assert [s for _, _, s in raw] == list(range(raw[0][2], raw[0][2] + 100))
    # an independent reader (rosbags, types from the file) sees the same values
    with AnyReader([files[0]], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        conn = [c for c in reader.connections if c.topic == f'{ns}/samples']
        forces = [reader.deserialize(raw, c.msgtype).force for c, _, raw in reader.messages(connections=conn)]
    np.testing.assert_array_equal(np.concatenate(forces), expected)


def run_recorder_process(ns, out_dir, extra=()):
    env = dict(os.environ, RMW_IMPLEMENTATION='rmw_fastrtps_cpp', ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(DOMAIN))
    return subprocess.Popen(
        [sys.executable, '-m', 'rubber_rig.nodes.recorder_node', '--ros-args', '-r', f'__ns:={ns}',
         '-p', f'output_dir:={out_dir}', '-p', 'flush_period:=0.1', '-p', 'diagnostics_period:=0.1',
         '-p', 'discovery_period:=0.1', '-p', 'metadata.specimen:=killed', *extra],
        env=env, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


# SIGKILL (what loses data) in make test; a clean SIGINT/SIGTERM stop, a node start each, in the system tier
@pytest.mark.parametrize('how', ['sigkill', pytest.param('sigint', marks=pytest.mark.system),
                                 pytest.param('sigterm', marks=pytest.mark.system)])
def test_recorder_process_killed_or_interrupted(context, tmp_path, how):
    """SIGKILL: every flushed batch is recovered; SIGINT/SIGTERM: clean shutdown, complete file."""
    ns = f'/proc_{how}'
    # all topics of the namespace, or an explicit list (relative names resolve in the namespace)
    proc = run_recorder_process(ns, tmp_path, () if how == 'sigkill' else ('-p', 'topics:=[samples]'))
    node = Node('fake_rig', namespace=ns, context=context)
    stats = {}

    def on_diag(msg):
        for s in msg.status:
            if s.hardware_id == str(tmp_path):
                stats.update({kv.key: kv.value for kv in s.values})
    with spinning(context, node) as executor:
        try:
            node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diag, 10)
            pub = node.create_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
            assert spin_until(executor, lambda: stats.get('topics') == '1' and pub.get_subscription_count() == 1)
            for k in range(50):
                pub.publish(batch(k))
                executor.spin_once(timeout_sec=0)
            # the recorder says all 50 are written and flushed to the OS
            assert spin_until(executor, lambda: stats.get('messages_flushed_current_file') == '50'), stats
            sig = {'sigkill': signal.SIGKILL, 'sigint': signal.SIGINT, 'sigterm': signal.SIGTERM}[how]
            proc.send_signal(sig)
            assert proc.wait(timeout=30) == (-signal.SIGKILL if how == 'sigkill' else 0), proc.stderr.read()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    [path] = tmp_path.glob('rubber_rig_*/*_0.mcap')
    if how == 'sigkill':
        assert cli(['recover', '--in-place', str(path)]) == 0
    r = load_recording(path)
    assert r.topics[f'{ns}/samples']['count'] == 50 and len(r) == 50 * BATCH and r.samples_lost == 0
    np.testing.assert_array_equal(r.force, np.concatenate([np.asarray(batch(k).force) for k in range(50)]))
    assert r.metadata['specimen'] == 'killed'
    assert bool(r.closing) == (how != 'sigkill')         # the closing report needs a clean stop


def test_control_service_split_and_snapshot(context, tmp_path):
    """SPLIT over ~/control: the two files hold every batch exactly once; SNAPSHOT: the last seconds."""
    ns = '/ctltest'
    pub_node = Node('fake_rig', namespace=ns, context=context)
    rec = RecorderNode(namespace=ns, context=context, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path)), Parameter('discovery_period', value=0.1),
        Parameter('snapshot_duration', value=30.0)])
    client_node = Node('client', context=context)
    with spinning(context, pub_node, rec, client_node) as executor:
        samples = pub_node.create_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
        control = client_node.create_client(RecorderControl, f'{ns}/recorder/control')
        assert control.wait_for_service(timeout_sec=10)

        call = control_caller(executor, control)
        assert rec.core.recording                                   # autostart
        graph = [('/ctltest/samples', ['a/msg/B']), ('/ctltest/run/_action/status', ['a/msg/C']),
                 ('/other/samples', ['a/msg/B']), ('/rosout', ['rcl_interfaces/msg/Log'])]
        assert rec.wanted_topics(graph) == graph[:1]               # own namespace, no hidden topics
        assert spin_until(executor, lambda: len(rec._subs) == 1)
        for k in range(60):
            if k == 25:
                assert spin_until(executor, lambda: rec.core.stats()['samples_seen'] == 25 * BATCH)
                response = call(RecorderControl.Request.SPLIT)
                assert response.success and response.file.endswith('_1.mcap'), response.message
            samples.publish(batch(k))
            executor.spin_once(timeout_sec=0)
        # samples seen, not messages written: a bookkeeping record may be written in the same wake-up
        assert spin_until(executor, lambda: rec.core.stats()['samples_seen'] == 60 * BATCH)
        snap = call(RecorderControl.Request.SNAPSHOT, str(tmp_path / 'snap.mcap'))
        assert snap.success, snap.message
        assert call(RecorderControl.Request.STOP).success
        assert call(99).success is False
    files = sorted(tmp_path.glob('rubber_rig_*/*.mcap'))
    parts = [load_recording(f) for f in files]
    assert [p.topics[f'{ns}/samples']['count'] for p in parts] == [25, 35]
    whole = load_recording(files[0].parent)
    np.testing.assert_array_equal(whole.sequence, np.arange(60 * BATCH))
    assert whole.samples_lost == 0
    snapshot = load_recording(tmp_path / 'snap.mcap')
    np.testing.assert_array_equal(snapshot.sequence, np.arange(60 * BATCH))   # all within 30 s
    assert snapshot.metadata['snapshot'] == 'true'


def test_unwritable_output_dir_is_reported_not_fatal(context, tmp_path):
    blocker = tmp_path / 'not_a_dir'
    blocker.write_text('x')
    rec = RecorderNode(namespace='/unwritable', context=context, parameter_overrides=[
        Parameter('output_dir', value=str(blocker / 'recordings')), Parameter('diagnostics_period', value=0.1)])
    client_node = Node('client', context=context)
    levels = []
    with spinning(context, rec, client_node) as executor:
        client_node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, lambda m: levels.extend(
            # fully qualified name: no collision
            (s.level, s.message) for s in m.status if s.name == '/unwritable/recorder: recording'), 10)
        assert not rec.core.recording
        assert spin_until(executor, lambda: levels)
        level, message = levels[0]
        assert level == DiagnosticStatus.ERROR and 'cannot create recording directory' in message
        control = client_node.create_client(RecorderControl, '/unwritable/recorder/control')
        assert control.wait_for_service(timeout_sec=10)
        future = control.call_async(signed(RecorderControl.Request(command=RecorderControl.Request.START,
                                                                   path=str(tmp_path / 'elsewhere')), RECORDER_CONTROL))
        assert spin_until(executor, future.done) and future.result().success
        assert rec.core.recording and rec.core.current_file.parent == tmp_path / 'elsewhere'


def test_a_forged_sample_batch_is_refused_counted_and_never_recorded(context, tmp_path, capsys):
    """Issue 35: a batch without the rig key's signature (a stranger's, sequence +1e6) or signed with another key is
    not written: the recorder counts it in its diagnostics (named with the topic) and in the file's close record,
    and the recording holds the driver's batches only, without a gap."""
    ns = '/forgetest'
    pub_node = Node('fake_rig', namespace=ns, context=context)
    rec = RecorderNode(namespace=ns, context=context, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path)), Parameter('autostart', value=False),
        Parameter('discovery_period', value=0.1), Parameter('diagnostics_period', value=0.2)])
    client_node = Node('client', context=context)
    other_key = client_auth('/forgetest/rig_driver', init_key(tmp_path / 'other.key'))
    with spinning(context, pub_node, rec, client_node) as executor:
        samples = pub_node.create_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
        control = client_node.create_client(RecorderControl, f'{ns}/recorder/control')
        assert control.wait_for_service(timeout_sec=10)
        call = control_caller(executor, control)
        out = tmp_path / 'run'
        assert call(RecorderControl.Request.START, str(out)).success
        assert spin_until(executor, lambda: len(rec._subs) == 1)
        forged = conv.sample_batch_msg(10**6, 0.0, PERIOD, np.zeros(BATCH), np.zeros(BATCH), np.zeros(BATCH), 23.0,
                                       0, 0)
        for msg in (batch(0), forged, other_key.sign(conv.sample_batch_msg(
                BATCH, 0.0, PERIOD, np.ones(BATCH), np.ones(BATCH), np.ones(BATCH), 23.0, 0, 0), SAMPLES), batch(1)):
            samples.publish(msg)
            executor.spin_once(timeout_sec=0)
        assert spin_until(executor, lambda: rec.core.stats()['messages_refused'] == 2
                          and rec.core.writer.messages_by_topic.get(f'{ns}/samples', 0) == 2)
        rec.publish_diagnostics()
        assert rec.auth.verifier.refused == {('samples', f'{ns}/samples'): 2}
        assert 'bad signature' in rec.auth.verifier.last_refusal.why
        assert call(RecorderControl.Request.STOP).success
    r = load_recording(sorted(out.glob('*.mcap'))[0])
    assert list(r.sequence) == list(range(2 * BATCH)) and r.samples_lost == 0
    assert r.closing[0]['messages_refused'] == 2
    assert r.closing[0]['messages_refused_by_topic'] == f'{ns}/samples: 2'
    assert cli(['info', str(out)]) == 0
    assert f'refused:    2 messages without the rig key\'s signature, not recorded ({ns}/samples: 2)' \
        in capsys.readouterr().out


def test_a_recorder_records_its_own_suite_not_another_on_the_domain(context, tmp_path):
    """A recorder in the root namespace (as `rubber-rig bench` runs it) records the topics its suite's nodes
    publish, not those of a second suite (/rig1) on the same domain."""
    ours, theirs = Node('fake_rig', context=context), Node('fake_rig', namespace='/rig1', context=context)
    rec = RecorderNode(context=context, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path)), Parameter('discovery_period', value=0.1)])
    with spinning(context, ours, theirs, rec) as executor:
        ours.create_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
        theirs.create_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
        theirs.create_publisher(RigStatus, topics.STATUS, topics.LATCHED_QOS)
        assert spin_until(executor, lambda: '/samples' in rec._subs, 10.0)
        spin_until(executor, lambda: False, 1.0)          # a second of discovery: /rig1's topics stay out
        assert set(rec._subs) == {'/samples'}, set(rec._subs)
