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

"""When the recorder publishes its status (recording.status_cadence), on simulated time: at once on a change, at
least every status_period otherwise. The node's status topic is tested in test_recording_node.py.
"""
from rubber_rig.recording.status_cadence import StatusCadence


def test_a_status_goes_out_on_a_change_and_at_least_every_period():
    cadence = StatusCadence(0.5)
    assert cadence.due(('recording', 'a.mcap'), 10.0)               # the first one
    assert not cadence.due(('recording', 'a.mcap'), 10.25)
    assert not cadence.due(('recording', 'a.mcap'), 10.5 - 1 / 1024)
    assert cadence.due(('recording', 'a.mcap'), 10.5)               # exactly one period after the last
    assert cadence.due(('error', 'a.mcap'), 10.5 + 1 / 1024)        # a change: at once
    assert cadence.key == ('error', 'a.mcap') and cadence.sent == 10.5 + 1 / 1024
    assert cadence.due(('error', 'a.mcap'), 10.75, force=True)
