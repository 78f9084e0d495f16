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

"""When the excitation node may start a program: a fresh rig status in a state that takes a stream nobody else
owns, our topics matched by DDS, (with require_recording) a recorder recording this namespace's samples, and a
program within the rig's limits. And when a running program must stop: held too long, the driver or (with
require_recording) the recorder gone.

Each check returns '' or why not, which is what a refused goal or a stopped program says.
"""
from __future__ import annotations

from rclpy.duration import Duration
from rclpy.node import Node

from msg_defs.msg import RigStatus
from rubber_rig.excitation import read_program
from rubber_rig.excitation.limits import check_program
from rubber_rig.nodes import awaitables
from rubber_rig.nodes import conversions as conv

NOW = Duration(seconds=0)    # wait_for_all_acked: ask, do not wait
READY_STATES = (RigStatus.STATE_IDLE, RigStatus.STATE_RUNNING, RigStatus.STATE_HOLDING)


def rig_ready(node: Node) -> str:
    """'' when the excitation ``node`` can start a program, else why not."""
    status, age = node.status, node.clock() - node.status_wall
    if status is None:
        return "no rig status received on 'status' yet (is rig_driver active?)"
    if age > node.status_timeout * 3:
        return f'the rig status is {age:.1f} s old (is rig_driver running?)'
    if status.state not in READY_STATES:
        why = '; '.join(status.fault_messages[-2:])
        return f'rig is {status.state_name}' + (f': {why} (rig_driver/reset to acknowledge)' if why else '')
    if status.stream_owner and status.stream_owner != node.get_fully_qualified_name():
        return f'the rig is streaming for {status.stream_owner}'
    if node.session is not None or node.opening:
        return 'a program is already running'
    return links_ready(node) or node.recording.ready()


def links_ready(node: Node) -> str:
    """'' once the node's setpoints publishers and samples subscription are matched with every endpoint the graph
    shows on those topics (the driver's among them). Right after a launch or a driver restart the status can
    arrive before they are: a stream opened then would run dry (no samples pace it) or send to nobody.
    """
    for what, matched, known in (
            ('samples subscription', node.sub_samples.get_publisher_count(),
             node.count_publishers(node.recording.samples_topic)),
            ('setpoint stream publisher', node.pub_stream.get_subscription_count(),
             node.count_subscribers(node.pub_stream.topic_name)),
            ('setpoints publisher', node.pub_setpoints.get_subscription_count(),
             node.count_subscribers(node.pub_setpoints.topic_name))):
        if matched < max(known, 1):
            return f'waiting for discovery: our {what} is matched with {matched} of {max(known, 1)} endpoints'
    # a reliable reader delivers in order: batches of an earlier stream that a broken network link lost are repaired
    # before anything newer, so a stream opened before that would reach the driver late and run dry
    if not node.pub_stream.wait_for_all_acked(NOW):
        return 'waiting for rig_driver to acknowledge the setpoints sent before (a network link came back?)'
    return ''


def statuses_fresh(node: Node, since: float) -> bool:
    """The rig status, the recorder status (with require_recording) and the node's topics are ready to judge a
    goal that arrived at ``since`` (node clock [s]).
    """
    rig = node.status is not None and node.clock() - node.status_wall <= node.status_timeout
    return rig and node.recording.fresh(since) and not links_ready(node)


def check_fits(node: Node, program) -> None:
    """Check the program against the rig's limits (and the node's force model) before anything is asked of the
    driver; ValueError names the block and field.
    """
    limits = conv.limits_from_msg(node.status.limits)
    limits.force_model = node.force_model
    check_program(limits, program, node.status.sample_rate)


def why_stop(node: Node) -> str:
    """Why the node's running program must stop now ('' if it runs on). Notes a lost recording first (the
    result of a program stopped for it says since when).
    """
    s = node.session
    if s.held:
        if node.clock() - node.held_wall > node.hold_timeout:
            return f'held for {node.hold_timeout:g} s without a resume (hold_timeout): ramp to rest'
        return ''
    if not s.stream_id:
        return ''
    node.recording.check(s.measured_sequence)
    # ages count only the time this node ran (StallWatch): after a stall of its own, the driver and the recorder get
    # their full timeout to be heard again before they are called silent
    if node.require_recording and node.recording.age > node.recorder_timeout:
        return f'recording lost: no recorder status for {node.recording.age:.1f} s (the recorder is gone)'
    silent = node.health.stall.since(node.driver_wall, node.clock())
    if silent > node.status_timeout:
        return (f'{node.rig_driver} silent for {silent:.1f} s (no status, no samples): the rig controller ramps '
                'to rest on its own host watchdog')
    return ''


async def wait_for_statuses(node: Node) -> None:
    """A goal sent right after launch (or a restart of the driver or recorder) may arrive before their latched
    statuses: wait for them (and for DDS to match our topics), at most the node's start_timeout.
    """
    since = node.clock()
    deadline = since + node.start_timeout
    while not statuses_fresh(node, since) and node.clock() < deadline:
        await awaitables.sleep(node, 0.05)


def load_program(node: Node, request, response):
    """~/load_program: read and validate a program against the rig's limits, without running it."""
    try:
        program, _ = read_program(request.path, request.program_yaml)
        rate = node.status.sample_rate if node.status else 1000.0
        if node.status is not None:
            check_fits(node, program)
        response.success, response.message = True, f"program '{program.name}' is valid"
        response.block_count, response.duration = len(program.blocks), program.duration(rate)
    except (ValueError, OSError) as exc:
        response.success, response.message = False, str(exc)
    except Exception as exc:   # noqa: BLE001 - a bad request must never take the node down
        response.success, response.message = False, f'internal error: {exc!r}'
    return response
