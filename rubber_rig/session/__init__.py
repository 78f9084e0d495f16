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


"""A test program run on a rig: the layer above excitation (what to move) and rig (how it moves), below the nodes
and the command line. Pure Python (no rclpy).
"""
from .admission import GoalAdmission
from .program_session import ProgramSession
from .rig_time import RigTime
from .run import ProgramRun, RunResult, run_program

__all__ = ['GoalAdmission', 'ProgramRun', 'ProgramSession', 'RigTime', 'RunResult', 'run_program']
