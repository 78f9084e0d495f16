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

"""Deliberate protocol defects of the simulated controller (rig.config SimOptions.defects).

Each one breaks one requirement of the rig protocol specification (docs/protocol.md) the way a real controller's
first firmware tends to, so that `rubber-rig conformance` can be shown to catch it. Never for use on a rig: a
defect makes the simulated controller unsafe in exactly the way it names.
"""

# defect name -> (requirement identifiers it breaks, what the controller then does). A new defect is one entry
# here, its flag in the simulator (rig/sim/) and nothing else: test_conformance runs every entry and expects
# exactly these requirements to fail.
DEFECTS = {
    'keep_setpoint_on_host_silence': (('CTRL-WD-1',), 'keeps holding the last setpoint when the host falls silent '
                                      'instead of ramping to rest'),
    'heartbeat_80ms': (('CTRL-HB-1',), 'sends ControllerHeartbeat every 80 ms instead of 50 ms'),
    'sequence_16bit': (('CTRL-SEQ-2',), 'counts the packed feedback sequence in 16 bits where the DBC specifies 32'),
    'ignore_host_limits': (('CTRL-LIM-1', 'CTRL-LIM-2'), 'ignores HostLimits: its own ramps and its setpoint check '
                           'use no displacement bounds'),
    'feedback_jitter': (('CTRL-FB-2',), 'sends each feedback frame 0-8 ms late (random, in order)'),
    'wrong_fault_bit': (('CTRL-FAULT-1',), 'reports host silence with the controller fault bit instead of watchdog'),
    'slow_ramp': (('CTRL-RAMP-1',), 'ramps to rest at a fifth of the commanded ramp velocity'),
    'buffer_in_frames': (('CTRL-ST-4',), 'reports ST_BufferLevel in setpoint frames queued instead of setpoints'),
    'no_heartbeat': (('CTRL-HB-1', 'CTRL-HB-2'), 'never sends ControllerHeartbeat (status, identity and feedback '
                     'as specified): a host must refuse to stream to it'),
    'rated_velocity_byte_swapped': (('CTRL-ID-3',), 'states its rated velocity (0.5 m/s) with the bytes of '
                                    'CI_VelocityMax swapped (3.4835 m/s); it still refuses steps above 0.5 m/s'),
    'ignore_lower_limit': (('CTRL-LIM-1', 'CTRL-LIM-2'), 'ignores HL_DisplacementMin: its ramps and its setpoint '
                           'check have no lower bound'),
    'velocity_check_upward_only': (('CTRL-LIM-3',), 'refuses setpoints too fast upwards only: a downward step of '
                                   'any size is applied'),
    'fault_clears_after_500ms': (('CTRL-FAULT-2',), 'leaves the fault state for idle by itself 0.5 s after the '
                                 'fault, without RESET'),
    'fault_ramp_step': (('CTRL-WD-1', 'CTRL-LIM-2'), 'starts its own ramps (faults, host silence) with a step of '
                        'up to 0.1 mm (100 mm/s for one sample at 1 kHz)'),
    'fault_ramp_overshoot': (('CTRL-WD-1', 'CTRL-LIM-2'), 'its own ramps (faults, host silence) pass their target '
                             'by 0.2 mm, then come back'),
    'identify_answered_once': (('CTRL-ID-1',), 'answers only the first IDENTIFY (the periodic identity goes on)'),
    'host_limits_crc_unchecked': (('CTRL-FRAME-2',), 'applies a HostLimits frame whatever its CRC'),
    'ignore_disable': (('CTRL-RAMP-1',), 'ignores DISABLE (ABORT works)'),
    'reset_while_ramping': (('CTRL-RESET-1',), 'honours RESET while ramping down: stops the ramp where it is, idle'),
    'feedback_six_per_frame': (('CTRL-FB-2',), 'gathers 6 samples into each packed feedback frame at 1 kHz (5 ms '
                               'of latency for the first; only the last sample of a frame is on time)'),
}


def check_defects(names) -> str:
    """'' when every name is a known defect, else what is wrong (for the configuration error)."""
    for name in names:
        if name not in DEFECTS:
            return f"unknown defect {name!r} (one of: {', '.join(DEFECTS)})"
    return ''
