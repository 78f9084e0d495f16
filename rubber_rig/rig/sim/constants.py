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

"""Constants of the simulated controller shared by its receive, tick and transmit sides."""

STREAMING = ('running', 'holding', 'ramping_down')
DEVICE_CODE = 0x5352      # ControllerIdentity.CI_Device of the simulated controller ('SR')
FIRMWARE = 1
IDLE_PERIOD = 0.01        # [s] the idle controller's housekeeping tick (ControllerStatus period)
LSB = 1e-7                # [m] displacement resolution of the setpoint frames
