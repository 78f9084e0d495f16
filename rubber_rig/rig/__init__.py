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

"""The rig: CAN protocol and driver over python-can (rig.can), the simulated servo-hydraulic rig (rig.sim),
configuration and open_rig (run_program, which needs a program too, is in rubber_rig.session). No rclpy.
"""
from .can.driver import DriverStatus, RigDriver, SampleBlock
from .can.protocol import (
                           FAULT_BUS,
                           FAULT_CONTROLLER,
                           FAULT_DISPLACEMENT_LIMIT,
                           FAULT_FORCE_LIMIT,
                           FAULT_NONE,
                           FAULT_SENSOR,
                           FAULT_VELOCITY_LIMIT,
                           FAULT_WATCHDOG,
                           STATES,
                           fault_names,
)
from .config import ConfigError, RigConfig, SimOptions
from .interface import Rig, open_rig
from .options import FaultSpec

__all__ = ['ConfigError', 'FAULT_BUS', 'FAULT_CONTROLLER', 'FAULT_DISPLACEMENT_LIMIT', 'FAULT_FORCE_LIMIT',
           'FAULT_NONE', 'FAULT_SENSOR', 'FAULT_VELOCITY_LIMIT', 'FAULT_WATCHDOG', 'FaultSpec', 'Rig', 'RigConfig',
           'RigDriver', 'DriverStatus', 'STATES', 'SampleBlock', 'SimOptions', 'fault_names',
           'open_rig']
