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


"""The safe envelope of the rig and the ramp that keeps it: the lowest layer of the product.

rig_driver is the one safety authority; it checks every streamed setpoint with `setpoint_violation`; the
excitation pre-checks whole programs against the same `Limits` (excitation.limits.check_program), and the
simulated controller ramps to rest with the same `SafeRamp`. Each limit, tolerance and ramp constant is defined
here once. Nothing in this package imports another part of rubber_rig except `settings`.
"""
from .envelope import LimitError, Limits, Violation, abort_ramp_velocity, setpoint_violation
from .ramp import BRAKE_DECEL, DECEL_MAX, RAMP_ACCEL, RAMP_VELOCITY, SafeRamp, braking_velocity, stopping_positions

__all__ = ['BRAKE_DECEL', 'DECEL_MAX', 'LimitError', 'Limits', 'RAMP_ACCEL', 'RAMP_VELOCITY', 'SafeRamp',
           'Violation', 'abort_ramp_velocity', 'braking_velocity', 'setpoint_violation', 'stopping_positions']
