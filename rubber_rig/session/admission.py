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

"""Goal admission: one program at a time, and every other goal turned away at once with the reason.

A goal that arrives while another runs is rejected before the action server makes it a goal handle: the cheapest
answer there is (an accepted goal costs two status messages listing every goal the server keeps, a result kept
for 15 min and a task). 200 goals accepted and then ended "busy" stalled the excitation past its 0.8 s heartbeat
silence and its stream ran dry at load 6; rejected at admission, the same burst left the program running
(test_foreign_requests). A rejection carries no text in ROS 2, so the reason and the count are kept here for
the log and the diagnostics.
"""
from __future__ import annotations


class GoalAdmission:
    """Which goal runs ('' when none), and the goals turned away since start (count, latest reason)."""

    def __init__(self):
        self.running = ''          # short id of the goal being executed
        self.rejected = 0
        self.last_rejection = ''

    def why_busy(self, program: str = '') -> str:
        """'' when a goal may start, else why not; `program`: the running program's name, when it has started."""
        if not self.running:
            return ''
        of = f"program '{program}' of " if program else ''
        return f'busy: {of}goal {self.running} is running; one program at a time'

    def reject(self, program: str = '') -> str:
        """The reason a goal arriving now is turned away ('' if it may start), counted."""
        why = self.why_busy(program)
        if why:
            self.rejected += 1
            self.last_rejection = why
        return why

    def reserve(self) -> None:
        """A goal was just accepted: busy from now, before it executes (rclpy starts it a spin later, and a goal
        admitted meanwhile would race it for the rig).
        """
        self.running = 'accepted'

    def start(self, goal_id: bytes) -> None:
        """Goal `goal_id` (its UUID bytes) is being executed."""
        self.running = bytes(goal_id).hex()[:8]

    def finish(self) -> None:
        """The goal being executed has ended (whatever its result)."""
        self.running = ''
