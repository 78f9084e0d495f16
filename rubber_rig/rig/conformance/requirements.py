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


"""The requirements of the rig protocol specification (docs/protocol.md), one entry each.

The specification's prose lives in docs/protocol.md; this table holds what a program needs of it: identifier,
title, who must meet it and whether a raw CAN log alone can show it (`offline`). test_protocol_spec checks that
every identifier here has its section in docs/protocol.md and the other way round.
"""
from dataclasses import dataclass


@dataclass(frozen=True)
class Requirement:
    """One requirement: `id` like 'CTRL-HB-1' (CTRL: the controller must, HOST: the host must), a short
    `title`, and `offline` True when a raw CAN log of normal operation is enough to check it.
    """

    id: str
    title: str
    offline: bool = False

    @property
    def party(self) -> str:
        return 'controller' if self.id.startswith('CTRL') else 'host'


REQUIREMENTS = (
    Requirement('CTRL-FRAME-1', 'every controller frame has its DBC length and a valid CRC-8', True),
    Requirement('CTRL-FRAME-2', 'a host frame with a wrong CRC or length is discarded, never applied'),
    Requirement('CTRL-FRAME-3', 'unknown identifiers, extended and remote frames are ignored'),
    Requirement('CTRL-ID-1', 'IDENTIFY is answered within 100 ms with the DBC protocol version'),
    Requirement('CTRL-ID-2', 'ControllerIdentity every 1000 ms', True),
    Requirement('CTRL-ID-3', 'the rated velocity stated is plausible: above 0, at most the envelope bound'),
    Requirement('CTRL-HB-1', 'ControllerHeartbeat every 50 ms', True),
    Requirement('CTRL-HB-2', 'heartbeat counter steps by one; HB_State is the current state', True),
    Requirement('CTRL-ST-1', 'ControllerStatus every 10 ms', True),
    Requirement('CTRL-ST-2', 'status counter steps by one; states and fault bits are defined values', True),
    Requirement('CTRL-ST-3', 'ST_LastSequence is the last sample taken', True),
    Requirement('CTRL-ST-4', 'ST_BufferLevel is the number of setpoints queued'),
    Requirement('CTRL-TEMP-1', 'Temperature every 100 ms', True),
    Requirement('CTRL-STREAM-1', 'a stream starts at the first setpoint at or after HS_FirstSequence'),
    Requirement('CTRL-STREAM-2', 'after a ramp to rest, no setpoint without a new HostStreamStart'),
    Requirement('CTRL-STREAM-3', 'an underrun holds the last command without a fault; the stream resumes'),
    Requirement('CTRL-STREAM-4', 'one setpoint per tick: the applied command is the setpoint of its sequence'),
    Requirement('CTRL-SEQ-1', 'feedback sequences are contiguous: no gap, no repeat', True),
    Requirement('CTRL-SEQ-2', 'sequence numbers have the DBC width and wrap at 2^bits', True),
    Requirement('CTRL-FB-1', 'feedback arrives at the sample rate', True),
    Requirement('CTRL-FB-2', 'feedback timing: at most 2 ms arrival jitter', True),
    Requirement('CTRL-WD-1', 'host silence: flush and ramp to rest within the stated host timeout'),
    Requirement('CTRL-RAMP-1', 'ABORT ramps to its target at the commanded velocity, without a step'),
    Requirement('CTRL-RAMP-2', 'HOLD brakes to a stop without a step'),
    Requirement('CTRL-LIM-1', "HostLimits bound the controller's own ramps"),
    Requirement('CTRL-LIM-2', 'a setpoint outside HostLimits is never applied: displacement_limit fault'),
    Requirement('CTRL-LIM-3', 'a setpoint faster than the rated velocity is never applied: velocity_limit fault'),
    Requirement('CTRL-FAULT-1', 'the fault bit names the cause, and no other bit is set'),
    Requirement('CTRL-FAULT-2', 'faults latch until RESET; RESET returns to idle without fault bits'),
    Requirement('CTRL-RESET-1', 'RESET while the rig moves is ignored'),
    Requirement('CTRL-PWR-1', 'power-up: idle, at rest, identity sent, no stream until HostStreamStart'),
    Requirement('CTRL-MEAS-1', 'force and displacement measure a reference spring within its uncertainty'),
    Requirement('CTRL-MEAS-2', 'force and displacement of one feedback sample are of the same tick'),
    Requirement('CTRL-MEAS-3', 'the temperature reported is plausible for the declared ambient'),
    Requirement('HOST-HB-1', 'HostHeartbeat every 50 ms while a stream is open', True),
    Requirement('HOST-LIM-1', 'HostLimits before the first setpoint', True),
    Requirement('HOST-STREAM-1', 'HostStreamStart before the first setpoint of every stream', True),
    Requirement('HOST-ID-1', 'IDENTIFY at start; no stream to a controller of another protocol version'),
    Requirement('HOST-WD-1', 'no stream before heartbeat, status and identity are heard; silence of any of them '
                'faults'),
)
BY_ID = {r.id: r for r in REQUIREMENTS}
