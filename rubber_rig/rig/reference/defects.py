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

"""Deliberate defects of the reference controller (ReferenceController(defects=...)), one per way a controller
written from the specification has been seen to go wrong (issue 36), each with the requirements of
docs/protocol.md a conformance run must then fail, and no others.

A new defect is one entry here and one flag test in the controller (controller.py, plant.py):
test_reference_controller runs every entry and expects exactly these requirements to fail. Never on a rig.
"""

# defect name -> (requirement identifiers it breaks, what the controller then does)
REFERENCE_DEFECTS = {
    'no_heartbeat': (('CTRL-HB-1', 'CTRL-HB-2'), 'never sends ControllerHeartbeat'),
    'watchdog_rearmed_by_any_frame': (('CTRL-WD-1',), 'its host watchdog is re-armed by any frame on the bus, not '
                                      'only HostHeartbeat: it never ramps while another node talks'),
    'fault_ramp_step': (('CTRL-WD-1', 'CTRL-LIM-2'), 'starts its own ramps (faults, host silence) with a step of '
                        'up to 0.5 mm in one sample'),
    'fault_ramp_overshoot': (('CTRL-WD-1', 'CTRL-LIM-2'), 'its own ramps pass their target by 0.2 mm, then come '
                             'back'),
    'ignore_lower_limit': (('CTRL-LIM-1', 'CTRL-LIM-2'), 'ignores HL_DisplacementMin (ramps and setpoint check)'),
    'velocity_check_upward_only': (('CTRL-LIM-3',), 'refuses too fast setpoints upwards only'),
    'rated_velocity_5ms': (('CTRL-ID-3',), 'states a rated velocity of 5 m/s (checks 0.5 m/s)'),
    'rated_velocity_byte_swapped': (('CTRL-ID-3',), 'sends CI_VelocityMax (0.5 m/s) with its bytes swapped'),
    'fault_clears_after_500ms': (('CTRL-FAULT-2',), 'a fault clears itself 0.5 s after it began, without RESET'),
    'setpoints_at_power_up': (('CTRL-PWR-1',), 'takes setpoints after power-up without a HostStreamStart'),
    'first_sequence_ignored': (('CTRL-STREAM-1',), 'starts a stream at the first setpoint after HostStreamStart, '
                               'whatever its sequence (HS_FirstSequence ignored)'),
    'identify_answered_once': (('CTRL-ID-1',), 'answers only the first IDENTIFY'),
    'reset_while_ramping': (('CTRL-RESET-1',), 'honours RESET while ramping down: stops where it is, idle'),
    'ignore_disable': (('CTRL-RAMP-1',), 'ignores DISABLE (ABORT works)'),
    'tighter_limits_spare_queued': (('CTRL-LIM-2',), 'HostLimits that tighten bind only the setpoints that arrive '
                                    'later: those already queued outside them are applied'),
    'queued_checked_when_applied': (('CTRL-LIM-2',), 'HostLimits that tighten refuse a queued setpoint outside them '
                                    'only when its tick comes, not when the limits arrive'),
    'host_limits_crc_unchecked': (('CTRL-FRAME-2',), 'applies a HostLimits frame whatever its CRC'),
    'feedback_six_per_frame': (('CTRL-FB-2',), 'sends feedback in frames of 6 samples (5 ms late for the first)'),
    'force_in_kN': (('CTRL-MEAS-1',), 'sends FB_Force in kN where the DBC says N'),
    'force_sign_inverted': (('CTRL-MEAS-1',), 'sends the force with its sign inverted (load cell wired backwards)'),
    'force_one_sample_late': (('CTRL-MEAS-2',), 'sends with each displacement the force of the tick before'),
    'displacement_gain_1_3': (('CTRL-MEAS-1',), 'its displacement transducer reads 1.3 x the true displacement '
                              '(the position loop closes on it: the specimen moves 1/1.3 of the command)'),
    'temperature_byte_swapped': (('CTRL-MEAS-3',), 'sends TEMP_Specimen with its two bytes swapped (23.45 degC '
                                 'reads 105.05 degC)'),
}


def check_reference_defects(names) -> str:
    """'' when every name is a defect of the reference controller, else what is wrong."""
    for name in names:
        if name not in REFERENCE_DEFECTS:
            return f"unknown reference controller defect {name!r} (one of: {', '.join(REFERENCE_DEFECTS)})"
    return ''
