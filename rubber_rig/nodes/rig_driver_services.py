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

"""rig_driver's stream services ~/open_stream and ~/stop_stream (`node`: the RigDriverNode), apart from its module.

Both take only requests signed with the rig's key (nodes/auth.py): a stranger can neither take the rig nor park it
where it likes. What a stream is and who may own it is the core driver's (rig.can.driver).
"""
from __future__ import annotations

import math

from msg_defs.srv import StopStream
from rubber_rig.nodes.auth import OPEN_STREAM, STOP_STREAM
from rubber_rig.rig.can.driver import StreamRefused


def open_stream(node, request, response):
    """~/open_stream (msg_defs/OpenStream, signed): the right to command the rig, one owner at a time."""
    if node.rig is None or not node.active:
        response.success, response.message = False, f'rig_driver is {node.lifecycle_state}, not active'
        return response
    driver = node.rig.driver
    if node.auth.refuse_request(node, request, OPEN_STREAM, response):   # a stranger cannot take the rig
        return response
    why = node.channels.listen_to(request.owner)   # (found in the graph already, unless the owner has just started)
    if why:
        response.success, response.message = False, why
        return response
    try:
        grant = driver.open_stream(request.owner, int(math.ceil(request.lead_time * node.config.sample_rate)))
    except StreamRefused as exc:
        response.success, response.message = False, str(exc)
        return response
    finally:
        node.log_events()
    response.success, response.message = True, f'stream {grant.stream_id} open'
    response.stream_id, response.first_sequence = grant.stream_id, grant.first_sequence
    response.position, response.velocity = grant.position, grant.velocity
    node.publish_status()
    return response


def stop_stream(node, request, response):
    """~/stop_stream (msg_defs/StopStream, signed): the owner stops now: abort (ramp to rest) or hold."""
    if node.rig is None:
        response.success, response.message = False, 'rig not configured'
        return response
    if node.auth.refuse_request(node, request, STOP_STREAM, response):   # nor park it where it likes
        return response
    why = node.rig.driver.stop_stream(request.stream_id, request.target, request.reason or 'stop requested',
                                      hold=request.action == StopStream.Request.ACTION_HOLD)
    node.log_events()
    node.publish_status()
    response.success, response.message = not why, why or 'ramping'
    return response
