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

"""The excitation node's services ~/abort and ~/hold (`node`: the ExcitationNode), apart from its module."""
from rubber_rig.nodes.auth import HOLD_PROGRAM


def on_abort(node, request, response):
    """~/abort (std_srvs/Trigger): ramp to the rest position now (anyone may: it makes the rig safer)."""
    if node.abort_program('operator abort (excitation/abort)'):
        response.success, response.message = True, 'the rig ramps to the rest position'
    else:
        response.success, response.message = False, 'no program running'
    return response


def on_hold(node, request, response):
    """~/hold (msg_defs/HoldProgram): true holds the running program at its block mean, false resumes it. A hold is
    taken from anyone (it stops the rig inside its limits); a resume moves the rig: only a signed one is taken.
    """
    s = node.session
    if not request.data and node.auth.refuse_request(node, request, HOLD_PROGRAM, response):
        return response
    if s is None:
        response.success, response.message = False, 'no program running'
    elif request.data:
        why = node.hold_program('operator hold (excitation/hold)')
        response.success = not why
        response.message = why or f'holding at {s.runner.hold_target * 1e3:.4f} mm (the block mean)'
    elif not s.held:
        response.success, response.message = False, 'not holding'
    else:
        node.executor.create_task(node._resume())
        response.success, response.message = True, 'resuming the held block with the cycles it has not run'
    return response
