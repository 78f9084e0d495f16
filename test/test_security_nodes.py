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

"""The nodes' side of signing (rubber_rig.nodes.auth) on real rosidl messages, without DDS traffic: what a signature
covers survives CDR serialization (what the recorder and every subscriber receive), any changed field breaks it, and
a node without a usable key refuses to start unless told it is a development set-up.
"""
import copy
import os

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message

from msg_defs.action import RunProgram
from msg_defs.msg import Heartbeat, RigStatus
from msg_defs.srv import HoldProgram, OpenStream, RecorderControl, StopStream
from rubber_rig.launching.inprocess import InProcessLauncher
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes.auth import (
    HEARTBEAT,
    OPEN_STREAM,
    RECORDER_CONTROL,
    RUN_PROGRAM,
    SAMPLES,
    SETPOINT_STREAM,
    STOP_STREAM,
    NodeAuth,
    annotate,
    declare_auth,
    fields_of,
)
from rubber_rig.nodes.excitation_node import ExcitationNode
from rubber_rig.nodes.params import ParameterError
from rubber_rig.nodes.rig_driver_node import RigDriverNode
from rubber_rig.security import init_key
from rubber_rig.testing.operator import Operator

from support.ros import ros_context
from support.suite import CONFIG, domain_id

KEY = bytes(range(32))


def make_node(context, **params):
    return Node('keyed', namespace='/auth_test', context=context, parameter_overrides=[
        Parameter(name, value=value) for name, value in params.items()])


def examples():
    x = np.sin(np.arange(100) * 0.01) * 1e-3
    return [
        (conv.sample_batch_msg(12345, 1.8e9, 1e-4, x, x * 1e6, x, 23.5, 4, 1), SAMPLES, ('first_sequence', 12346)),
        (conv.setpoint_batch_msg(500, 1e-3, x[:20], 2, t=1.8e9, stream_id=77, source='/rig1/excitation',
                                 end_of_stream=False), SETPOINT_STREAM, ('end_of_stream', True)),
        (Heartbeat(node='/rig1/excitation', pid=42, count=9, state='running'), HEARTBEAT, ('count', 10)),
        (OpenStream.Request(owner='/rig1/excitation', lead_time=0.5), OPEN_STREAM, ('owner', '/rig1/intruder')),
        (StopStream.Request(stream_id=77, action=StopStream.Request.ACTION_HOLD, target=0.0, reason='hold'),
         STOP_STREAM, ('target', 3e-3)),
        (RecorderControl.Request(command=RecorderControl.Request.STOP), RECORDER_CONTROL, ('path', '/tmp/x')),
        (RunProgram.Goal(program_yaml='name: p', amplitude_control=True), RUN_PROGRAM, ('program_path', '/dev/zero')),
    ]


@pytest.mark.parametrize('msg, purpose, change', examples(), ids=lambda v: getattr(v, '__name__', None))
def test_a_signature_survives_cdr_and_breaks_on_any_change(msg, purpose, change):
    signer, receiver = NodeAuth('/rig1/signer', KEY, True, '-'), NodeAuth('/rig1/receiver', KEY, True, '-')
    signer.sign(msg, purpose)
    assert len(bytes(msg.signature.tag)) == 32 and msg.signature.link == '/rig1/signer'
    received = deserialize_message(serialize_message(msg), type(msg))
    assert receiver.verify(received, purpose, '/ch') == ''
    assert 'replayed' in receiver.verify(deserialize_message(serialize_message(msg), type(msg)), purpose, '/ch')
    altered = copy.deepcopy(msg)
    setattr(altered, *change)
    assert 'bad signature' in receiver.verify(altered, purpose, '/ch')
    assert 'bad signature' in receiver.verify(signer.sign(copy.deepcopy(msg), purpose), 'other purpose', '/ch')
    unsigned = type(msg)(**{name: getattr(msg, name) for name in msg.get_fields_and_field_types()
                            if name != 'signature'})
    assert 'unsigned' in receiver.verify(unsigned, purpose, '/ch')
    assert receiver.verifier.refused_total == 4


def test_every_field_but_the_signature_is_covered():
    msg = conv.sample_batch_msg(1, 2.0, 1e-3, [1.0], [2.0], [3.0], 23.0, 0, 0)
    names = [name for name, _ in fields_of(msg)]
    assert names == ['header.stamp.sec', 'header.stamp.nanosec', 'header.frame_id', 'first_sequence', 'sample_period',
                     'displacement', 'force', 'setpoint', 'temperature', 'status_flags', 'frames_lost']


@pytest.mark.ros
def test_a_node_without_a_usable_key_refuses_to_start_unless_in_development_mode(tmp_path):
    with ros_context() as context:
        node = make_node(context, **{'auth.key_file': str(tmp_path / 'missing.key')})
        with pytest.raises(ParameterError, match=r"auth.key_file.*no key file at .*missing.key.*rubber-rig keys init"):
            declare_auth(node)
        node.destroy_node()
        readable = init_key(tmp_path / 'rig.key')
        os.chmod(readable, 0o644)
        node = make_node(context, **{'auth.key_file': str(readable)})
        with pytest.raises(ParameterError, match=r'mode 0644: its group or other users can read'):
            declare_auth(node)
        node.destroy_node()
        node = make_node(context, **{'auth.key_file': str(tmp_path / 'missing.key'), 'auth.required': False})
        auth = declare_auth(node)
        assert auth.off and auth.verify(Heartbeat(node='/x'), HEARTBEAT, '/hb') == ''
        status = annotate(DiagnosticStatus(level=DiagnosticStatus.OK, message='idle'), auth)
        assert status.level == DiagnosticStatus.WARN and status.message.startswith('AUTHENTICATION OFF')
        assert {kv.key: kv.value for kv in status.values}['auth'].startswith('OFF')
        node.destroy_node()
        os.chmod(readable, 0o600)
        node = make_node(context, **{'auth.key_file': str(readable)})
        auth = declare_auth(node)
        assert not auth.off and auth.signer.link == '/auth_test/keyed'
        forged = Heartbeat(node='/auth_test/other')
        auth.verify(forged, HEARTBEAT, '/auth_test/heartbeat')
        status = annotate(DiagnosticStatus(level=DiagnosticStatus.OK, message='idle'), auth)
        assert status.level == DiagnosticStatus.WARN
        assert status.message.startswith('1 unauthenticated messages refused (heartbeat on /auth_test/heartbeat')
        node.destroy_node()


@pytest.mark.ros
def test_rig_driver_takes_commands_only_signed_with_the_rig_key():
    """Wiring, in one process (no program on the wall clock): a stranger's open_stream is refused, the operator's
    signed one granted; on the granted channel an unsigned batch is refused and counted, a signed one queued; a
    stranger's stop_stream is refused, the owner's signed one ramps. The refusals are named with their channel."""
    ns = '/sectest'
    with InProcessLauncher([CONFIG], namespace=ns, domain_id=domain_id()) as launcher:
        driver = launcher.start(RigDriverNode)
        op, stranger = Operator(ns, domain_id()), Operator(ns, domain_id(), name='stranger', signs=False)
        try:
            assert op.wait_status(lambda s: s.state == RigStatus.STATE_IDLE, 30.0), 'rig_driver not idle'
            refused = stranger.call('rig_driver/open_stream', OpenStream,
                                    OpenStream.Request(owner=f'{ns}/stranger', lead_time=0.5))
            assert refused is not None and not refused.success and refused.message.startswith('refused: unsigned')
            owner = f'{ns}/operator'
            grant = op.call('rig_driver/open_stream', OpenStream, OpenStream.Request(owner=owner, lead_time=2.0))
            assert grant is not None and grant.success, grant
            assert launcher.wait_for(lambda: op.pub_setpoints['command'].get_subscription_count() >= 1, 10.0)
            x = np.full(500, grant.position)
            unsigned = conv.setpoint_batch_msg(grant.first_sequence, 1e-3, x, 0, stream_id=grant.stream_id,
                                               source=owner)
            op.pub_setpoints['command'].publish(unsigned)
            assert launcher.wait_for(lambda: driver.rig.driver.status.extra['setpoints_refused'] >= 500, 5.0)
            op.pub_setpoints['command'].publish(op.sign(copy.deepcopy(unsigned), SETPOINT_STREAM))
            assert launcher.wait_for(lambda: driver.rig.driver.status.extra['next_sequence']
                                     >= grant.first_sequence + 500, 5.0), driver.rig.driver.status.extra
            stop = StopStream.Request(stream_id=grant.stream_id, action=StopStream.Request.ACTION_ABORT, target=0.0)
            refused = stranger.call('rig_driver/stop_stream', StopStream, copy.deepcopy(stop))
            assert refused is not None and not refused.success and 'unsigned' in refused.message
            assert op.call('rig_driver/stop_stream', StopStream, stop).success
            lines = driver.auth.lines()
            assert lines['auth_refused_by_channel'] == (
                f'open_stream on {ns}/rig_driver/open_stream: 1, setpoint_stream on '
                f'rig_driver/setpoint_stream/{owner[1:]}: 1, stop_stream on {ns}/rig_driver/stop_stream: 1')
        finally:
            stranger.close()
            op.close()


@pytest.mark.ros
def test_anyone_may_hold_a_program_but_only_a_signed_request_resumes_one():
    """A hold stops the rig inside its limits (like an abort: open to all); a resume moves it. The stranger's
    resume is refused before anything else is looked at; the operator's signed one gets through to the program
    check (here: no program runs), as does anyone's hold."""
    ns = '/holdtest'
    with InProcessLauncher([CONFIG], namespace=ns, domain_id=domain_id()) as launcher:
        excitation = launcher.start(ExcitationNode)
        op, stranger = Operator(ns, domain_id()), Operator(ns, domain_id(), name='stranger', signs=False)
        try:
            refused = stranger.call('excitation/hold', HoldProgram, HoldProgram.Request(data=False), 10.0)
            assert refused is not None and not refused.success and refused.message.startswith('refused: unsigned')
            hold = stranger.call('excitation/hold', HoldProgram, HoldProgram.Request(data=True))
            assert hold is not None and hold.message == 'no program running'
            resume = op.hold(False)
            assert resume is not None and resume.message == 'no program running', resume
            lines = excitation.auth.lines()
            assert lines['auth_refused_by_channel'] == f'hold_program on {ns}/excitation/hold_program: 1', lines
        finally:
            stranger.close()
            op.close()
