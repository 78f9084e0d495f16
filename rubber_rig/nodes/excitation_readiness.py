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

"""The excitation node's side of its start rules (rubber_rig.session.program_watch.ProgramWatch decides): the
graph's facts about its topics as plain values, the check of a program against the rig's limits, the wait for
fresh statuses of a goal that arrives right after a launch, and the ~/load_program service.
"""
from __future__ import annotations

from rclpy.duration import Duration
from rclpy.node import Node

from msg_defs.msg import RigStatus
from rubber_rig.excitation import read_program
from rubber_rig.excitation.limits import check_program
from rubber_rig.nodes import awaitables
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes.excitation_recording import publishers, recorder_topic, samples_topic
from rubber_rig.session import program_watch
from rubber_rig.session.program_watch import RigView, links_verdict

NOW = Duration(seconds=0)    # wait_for_all_acked: ask, do not wait
READY_STATES = tuple(conv.STATE_BY_NAME[name] for name in program_watch.READY_STATES)   # as RigStatus.STATE_* codes


def rig_view(msg: RigStatus) -> RigView:
    """msg_defs/RigStatus -> the RigView the start and stop rules read."""
    faulted = msg.state == RigStatus.STATE_FAULT or bool(msg.faults)
    return RigView(conv.STATE_NAMES.get(msg.state, msg.state_name), faulted,
                   list(msg.fault_messages or (conv.fault_names(msg.faults) if msg.faults else [])),
                   msg.stream_owner, int(msg.stream_id), msg.last_event)


def links(node: Node) -> str:
    """The graph's facts on the node's samples subscription and setpoint publishers (matched / shown endpoints, and
    whether the driver acknowledged what was sent) judged by program_watch.links_verdict.
    """
    return links_verdict((
        ('samples subscription', node.sub_samples.get_publisher_count(), node.count_publishers(samples_topic(node))),
        ('setpoint stream publisher', node.pub_stream.get_subscription_count(),
         node.count_subscribers(node.pub_stream.topic_name)),
        ('setpoints publisher', node.pub_setpoints.get_subscription_count(),
         node.count_subscribers(node.pub_setpoints.topic_name))), node.pub_stream.wait_for_all_acked(NOW))


def recording_ready(node: Node, now: float) -> str:
    """The recorder watch's verdict on a start, with the graph's publishers of the recorder status and samples."""
    return node.recording.why_not_start(now, publishers(node, recorder_topic(node)),
                                        publishers(node, samples_topic(node)))


def recording_fresh(node: Node, since: float, now: float) -> bool:
    return node.recording.fresh(since, now, publishers(node, recorder_topic(node)),
                                publishers(node, samples_topic(node)))


def check_fits(node: Node, program) -> None:
    """Check the program against the rig's limits (and the node's force model) before anything is asked of the
    driver; ValueError names the block and field.
    """
    limits = conv.limits_from_msg(node.status.limits)
    limits.force_model = node.params.force_model
    check_program(limits, program, node.status.sample_rate)


async def wait_for_statuses(node: Node) -> None:
    """A goal sent right after launch (or a restart of the driver or recorder) may arrive before their latched
    statuses: wait for them (and for DDS to match our topics), at most the node's start_timeout.
    """
    since = node.clock()
    while not node.watch.start_wait_over(since, node.clock()) and not node.watch.statuses_fresh(
            node.clock(), recording_fresh(node, since, node.clock()), links(node)):
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
