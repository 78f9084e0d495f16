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

"""CAN side of the rig: the DBC protocol and the host driver over any python-can Bus."""
from .protocol import (
                       DBC_PATH,
                       FAULT_BUS,
                       FAULT_CONTROLLER,
                       FAULT_DISPLACEMENT_LIMIT,
                       FAULT_FORCE_LIMIT,
                       FAULT_NAMES,
                       FAULT_NONE,
                       FAULT_SENSOR,
                       FAULT_STREAM,
                       FAULT_VELOCITY_LIMIT,
                       FAULT_WATCHDOG,
                       STATES,
                       MalformedFrame,
                       Protocol,
                       fault_names,
)

__all__ = ['DBC_PATH', 'FAULT_BUS', 'FAULT_CONTROLLER', 'FAULT_DISPLACEMENT_LIMIT', 'FAULT_FORCE_LIMIT',
           'FAULT_NAMES', 'FAULT_NONE', 'FAULT_SENSOR', 'FAULT_STREAM', 'FAULT_VELOCITY_LIMIT', 'FAULT_WATCHDOG',
           'STATES', 'MalformedFrame', 'Protocol', 'fault_names']
