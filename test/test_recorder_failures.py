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

"""Recorder failures with real rclpy + Fast DDS: unwritable / uncreatable output directories, a disk that fills
up mid-recording (a real ENOSPC on a small tmpfs in a private mount namespace), SIGKILL mid-stream, and loss
accounting (a sequence jump between programs is not loss; the driver's frames_lost is). The recorder runs as
its own process where the failure needs it (mount namespace, SIGKILL), in-process otherwise."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from msg_defs.msg import RecorderStatus, RigSampleBatch
from msg_defs.srv import RecorderControl
from rubber_rig.cli.main import main as cli
from rubber_rig.nodes import topics
from rubber_rig.nodes.auth import RECORDER_CONTROL, signed
from rubber_rig.nodes.recorder_node import RecorderNode
from rubber_rig.recording import GapTracker, load_recording, recover

from support.mounts import IN_PRIVATE_MOUNT, private_mounts_available
from support.ros import ros_context, sample_batch, spin_until, spinning

REPO = Path(__file__).resolve().parents[1]
DOMAIN = 200 + os.getpid() % 30          # a domain of our own (other test modules use 20-199)
PERIOD = 1e-3


@pytest.fixture
def context():
    with ros_context(DOMAIN) as ctx:
        yield ctx


def batch(first, n=20, frames_lost=0):
    return sample_batch(first, n, period=PERIOD, frames_lost=frames_lost)


class Client:
    """The test's side of the ROS graph: a fake rig publishing samples, the recorder's status and control."""

    def __init__(self, context, ns):
        self.ns = ns
        self.node = Node('fake_rig', namespace=ns, context=context)
        self.pub = self.node.create_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
        self.statuses = []            # (monotonic time received, RecorderStatus)
        self.node.create_subscription(RecorderStatus, topics.RECORDER_STATUS,
                                      lambda m: self.statuses.append((time.monotonic(), m)), topics.LATCHED_QOS)
        self.diagnostics = []
        self.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS,
                                      lambda m: self.diagnostics.extend(m.status), 10)
        self.control = self.node.create_client(RecorderControl, f'{ns}/recorder/control')

    @property
    def status(self):
        return self.statuses[-1][1] if self.statuses else None

    def recording_samples(self):
        st = self.status
        return st is not None and st.state == RecorderStatus.STATE_RECORDING and f'{self.ns}/samples' in st.topics

    def call(self, executor, command, path=''):
        assert self.control.wait_for_service(timeout_sec=20)
        future = self.control.call_async(signed(RecorderControl.Request(command=command, path=path),
                                                RECORDER_CONTROL))
        assert spin_until(executor, future.done)
        return future.result()


def recorder_process(ns, params, prefix=(), script=None):
    """The recorder as its own process (``python -m rubber_rig.nodes.recorder_node``), on the test's domain."""
    env = dict(os.environ, RMW_IMPLEMENTATION='rmw_fastrtps_cpp', ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(DOMAIN))
    args = [sys.executable, '-m', 'rubber_rig.nodes.recorder_node', '--ros-args', '-r', f'__ns:={ns}']
    for k, v in params.items():
        args += ['-p', f'{k}:={v}']
    if script is not None:      # run inside a shell script (private mounts): it gets the command as "$@"
        args = [*prefix, 'sh', '-c', script, 'sh', *args]
    return subprocess.Popen(args, env=env, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def stop_process(proc, sig=signal.SIGTERM, timeout=30):
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


# -- unwritable / uncreatable output directory ---------------------------------------------------------------------
@pytest.mark.ros
def test_uncreatable_output_dir_is_an_error_status_then_start_elsewhere_records(context, tmp_path):
    blocker = tmp_path / 'a_file'
    blocker.write_text('x')
    ns = '/uncreatable'
    rec = RecorderNode(namespace=ns, context=context, parameter_overrides=[
        Parameter('output_dir', value=str(blocker / 'recordings')), Parameter('discovery_period', value=0.1),
        Parameter('diagnostics_period', value=0.1)])
    client = Client(context, ns)
    with spinning(context, rec, client.node) as executor:
        assert spin_until(executor, lambda: client.status is not None)
        st = client.status
        assert st.state == RecorderStatus.STATE_ERROR and st.state_name == 'error'
        assert str(blocker / 'recordings') in st.error and 'Not a directory' in st.error
        assert st.path == ''
        # diagnostics: ERROR, named after the fully qualified node, hardware_id the absolute output dir
        assert spin_until(executor, lambda: any(d.name == f'{ns}/recorder: recording' for d in client.diagnostics))
        d = [d for d in client.diagnostics if d.name == f'{ns}/recorder: recording'][-1]
        assert d.level == DiagnosticStatus.ERROR and d.hardware_id == str(blocker / 'recordings')
        # a START to the same place is refused with the reason; the node lives on
        refused = client.call(executor, RecorderControl.Request.START)
        assert not refused.success and 'Not a directory' in refused.message
        good = client.call(executor, RecorderControl.Request.START, str(tmp_path / 'good'))
        assert good.success, good.message
        assert spin_until(executor, client.recording_samples), client.status
        assert client.status.path == good.file and client.status.error == ''
        for k in range(10):
            client.pub.publish(batch(k * 20))
        assert spin_until(executor, lambda: client.status.messages_written == 10)   # within status_period
        assert client.call(executor, RecorderControl.Request.STOP).success
        assert spin_until(executor, lambda: client.status.state == RecorderStatus.STATE_IDLE)
    r = load_recording(tmp_path / 'good')
    assert len(r) == 200 and r.samples_lost == 0 and r.complete


@pytest.mark.ros
@pytest.mark.system     # a node start of its own; the uncreatable directory (make test) takes the same path
def test_read_only_output_dir_is_an_error_status_and_a_later_start_works(context, tmp_path):
    why = private_mounts_available()
    if why:
        pytest.skip(why)
    ro = tmp_path / 'ro'
    ro.mkdir()
    (tmp_path / 'copy').mkdir()
    ns = '/readonly'
    script = IN_PRIVATE_MOUNT.format(setup=f'mount --bind {ro} {ro} && mount -o remount,bind,ro {ro}',
                                     mnt=ro, visible=tmp_path / 'copy')
    proc = recorder_process(ns, {'output_dir': ro, 'discovery_period': 0.1},
                            prefix=('unshare', '-m', '--propagation', 'private'), script=script)
    client = Client(context, ns)
    try:
        with spinning(context, client.node) as executor:
            assert spin_until(executor, lambda: client.status is not None, 30), proc.stderr
            st = client.status
            assert st.state == RecorderStatus.STATE_ERROR, st
            assert str(ro) in st.error and 'Read-only file system' in st.error
            assert proc.poll() is None                       # alive, no traceback
            good = client.call(executor, RecorderControl.Request.START, str(tmp_path / 'good'))
            assert good.success, good.message
            assert spin_until(executor, client.recording_samples)
            for k in range(5):
                client.pub.publish(batch(k * 20))
            assert spin_until(executor, lambda: client.status.messages_written == 5)
        assert stop_process(proc) == 0
    finally:
        stop_process(proc, signal.SIGKILL)
    err = proc.stderr.read()
    assert 'Traceback' not in err and 'Read-only file system' in err
    assert len(load_recording(tmp_path / 'good')) == 100
    assert not list(ro.iterdir())                            # nothing was written to the read-only dir


# -- disk full mid-recording -------------------------------------------------------------------------------------------
@pytest.mark.ros
def test_disk_full_mid_recording_is_an_error_within_half_a_second_and_the_file_stays_readable(context, tmp_path):
    why = private_mounts_available()
    if why:
        pytest.skip(why)
    mnt, visible = tmp_path / 'small_disk', tmp_path / 'copy'
    mnt.mkdir()
    visible.mkdir()
    ns = '/diskfull'
    script = IN_PRIVATE_MOUNT.format(setup=f'mount -t tmpfs -o size=1m tmpfs {mnt}', mnt=mnt, visible=visible)
    # uncompressed, small chunks: a batch of 1000 samples (24 kB) closes a chunk, so every message is a write
    proc = recorder_process(ns, {'output_dir': mnt, 'compression': 'none', 'chunk_size': 16,
                                 'discovery_period': 0.1},
                            prefix=('unshare', '-m', '--propagation', 'private'), script=script)
    client = Client(context, ns)
    n = 1000
    published = []
    try:
        with spinning(context, client.node) as executor:
            assert spin_until(executor, client.recording_samples, 30), proc.stderr
            path = client.status.path
            for k in range(200):                            # 24 MB offered to a 1 MB disk
                client.pub.publish(batch(k * n, n))
                published.append(k)
                executor.spin_once(timeout_sec=0.01)
                if client.status.state == RecorderStatus.STATE_ERROR:
                    break
            assert client.status.state == RecorderStatus.STATE_ERROR, 'the disk never filled up'
            t_error = next(t for t, s in client.statuses if s.state == RecorderStatus.STATE_ERROR)
            st = client.status
            assert 'disk full' in st.error and path in st.error and st.path == path
            # batches that arrive after the error are counted as lost, not silently dropped
            for k in range(len(published), len(published) + 10):
                client.pub.publish(batch(k * n, n))
            assert spin_until(executor, lambda: client.status.samples_lost >= 10 * n), client.status
            assert proc.poll() is None                       # the recorder survives
        assert stop_process(proc) == 0
    finally:
        stop_process(proc, signal.SIGKILL)
    assert 'Traceback' not in proc.stderr.read()
    [copy] = visible.glob('rubber_rig_*/*_0.mcap')
    # the mcap library reads the unclosed file up to its last complete chunk ...
    with open(copy, 'rb') as f:
        intact = []
        try:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Message):
                    intact.append(record)
        except Exception:  # noqa: BLE001 - the partial record at the end of a full disk
            pass
    assert 0 < len(intact) < len(published)
    # ... and the ERROR arrived within 0.5 s of the last write that succeeded (the failed one came after it)
    last_intact_wall = intact[-1].log_time / 1e9
    error_wall = time.time() - (time.monotonic() - t_error)
    assert error_wall - last_intact_wall < 0.5, error_wall - last_intact_wall
    r = load_recording(copy, allow_truncated=True)
    assert not r.complete and r.unclosed and r.tail_unaccounted
    assert r.sequence[0] == 0 and len(r) == len(intact) * n and r.samples_lost == 0
    np.testing.assert_array_equal(r.force, np.concatenate([np.asarray(batch(k * n, n).force)
                                                           for k in range(len(intact))]))
    assert 'NOT CLOSED' in r.loss_text() and 'unaccounted' in r.loss_text()
    # rebuilt, the file is complete for every reader: mcap's indexed reader and rosbags
    result = recover(copy, tmp_path / 'recovered.mcap')
    assert not result.was_complete and result.messages == len(intact) and result.tail_unaccounted
    assert result.last_sequence == len(intact) * n - 1
    with open(tmp_path / 'recovered.mcap', 'rb') as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == len(intact)
    with AnyReader([tmp_path / 'recovered.mcap'], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        forces = [reader.deserialize(raw, c.msgtype).force for c, _, raw in reader.messages()]
    np.testing.assert_array_equal(np.concatenate(forces), r.force)


# -- SIGKILL mid-stream ------------------------------------------------------------------------------------------------
@pytest.mark.ros
@pytest.mark.system     # 15 s of stream; a killed recorder is make test's in test_fault_matrix and test_recording_node
def test_sigkill_mid_stream_loses_at_most_the_flush_period_and_says_the_tail_is_unaccounted(context, tmp_path,
                                                                                            capsys):
    ns = '/killed'
    proc = recorder_process(ns, {'output_dir': tmp_path})      # default flush_period (0.25 s)
    client = Client(context, ns)
    last_sent = -1
    try:
        with spinning(context, client.node) as executor:
            assert spin_until(executor, client.recording_samples, 30), proc.stderr
            t0 = time.monotonic()
            k = 0
            while time.monotonic() - t0 < 2.0:                 # 1 kHz in batches of 20, paced
                client.pub.publish(batch(k * 20))
                last_sent = k * 20 + 19
                k += 1
                next_at = t0 + k * 0.02
                while time.monotonic() < next_at:
                    executor.spin_once(timeout_sec=max(0.0, next_at - time.monotonic()))
            proc.send_signal(signal.SIGKILL)
            assert proc.wait(timeout=30) == -signal.SIGKILL
    finally:
        stop_process(proc, signal.SIGKILL)
    [path] = tmp_path.glob('rubber_rig_*/*_0.mcap')
    r = load_recording(path, allow_truncated=True)
    [u] = r.unclosed
    assert u['file'] == str(path) and u['last_sequence'] == r.sequence[-1]
    missing = last_sent - int(r.sequence[-1])
    assert 0 <= missing <= 400, missing                         # 0.25 s flush period + delivery, at 1 kHz
    text = r.loss_text()
    assert 'NOT CLOSED' in text and f"last sample sequence {u['last_sequence']}" in text and 'unaccounted' in text
    assert cli(['info', str(path)]) == 0
    assert 'truncated' in capsys.readouterr().out
    result = recover(path)
    assert result.tail_unaccounted and result.last_sequence == u['last_sequence']
    assert 'NOT CLOSED' in result.loss_text() and 'unaccounted' in result.loss_text()
    assert load_recording(result.output).complete


# -- loss accounting -----------------------------------------------------------------------------------------------
@pytest.mark.ros
def test_program_to_program_jump_is_not_loss_but_the_drivers_frames_lost_is(context, tmp_path):
    ns = '/jumps'
    rec = RecorderNode(namespace=ns, context=context, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path)), Parameter('discovery_period', value=0.1),
        Parameter('diagnostics_period', value=0.1)])
    client = Client(context, ns)
    with spinning(context, rec, client.node) as executor:
        assert spin_until(executor, client.recording_samples)
        for k in range(30):                                   # program 1: samples 0..599
            client.pub.publish(batch(k * 20))
        start2 = 600 + 516                                    # the rig idled; program 2 starts lead_time later
        for k in range(30):
            client.pub.publish(batch(start2 + k * 20))
        assert spin_until(executor, lambda: client.status.messages_written == 60)
        mine = lambda: [d for d in client.diagnostics if d.name == f'{ns}/recorder: recording']  # noqa: E731
        n_diag = len(mine())
        assert spin_until(executor, lambda: len(mine()) > n_diag + 1)
        assert mine()[-1].level == DiagnosticStatus.OK, mine()[-1].message        # no false WARN
        assert client.status.samples_lost == 0
        # 5 samples lost on the bus: the driver's next batch starts 5 later and says so in frames_lost
        client.pub.publish(batch(start2 + 600 + 5, frames_lost=5))
        assert spin_until(executor, lambda: client.status.samples_lost == 5)
        assert spin_until(executor, lambda: mine()[-1].level == DiagnosticStatus.WARN)
        assert '5 samples lost' in mine()[-1].message
        assert client.call(executor, RecorderControl.Request.STOP).success
    [bag] = tmp_path.glob('rubber_rig_*')
    r = load_recording(bag)
    assert r.samples_lost == 5 and len(r.gaps) == 1 and r.gaps[0]['frames_lost'] == 5
    assert len(r.jumps) == 1 and r.jumps[0]['expected'] == 600 and r.jumps[0]['received'] == start2
    assert r.closing[0]['samples_lost'] == 5 and r.closing[0]['sequence_jumps'] == 1


def test_gap_tracker_counts_messages_missed_in_transport():
    """Without frames_lost, a gap is loss exactly when the DDS publication sequence skipped too."""
    g = GapTracker()
    g.observe('/s', 0, 20, publication_sequence=1)
    g.observe('/s', 20, 20, publication_sequence=2)
    g.observe('/s', 100, 20, publication_sequence=3)         # nothing published in between: a jump
    assert g.samples_lost == 0 and g.jumps == 1 and g.samples_skipped == 60
    g.observe('/s', 160, 20, publication_sequence=6)         # two messages (40 samples) never arrived
    assert g.samples_lost == 40 and g.gaps == 1
    g.observe('/s', 190, 20, frames_lost=10, publication_sequence=7)   # bus loss reported by the driver
    assert g.samples_lost == 50 and g.frames_lost == 10 and g.gaps == 2
    g.observe('/s', 215, 20)                                  # unknown publication sequence: conservative
    assert g.samples_lost == 55
