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

"""What the parts of the simulated controller share, in one place: the state machine's state and faults, the
sample clock, the setpoint queue, the applied command, what the host has said (stream start, heartbeat, limits)
and the counters. The controller's tick writes it, the receiver (receive.CommandReceiver) changes it as the
host's frames say, the transmitter (transmit.FeedbackTransmitter) reports it in the status frames.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from ...safety import DECEL_MAX


def _counters() -> dict:
    return {'underruns': 0, 'setpoints_late': 0, 'frames_bad': 0, 'overruns': 0, 'tx_dropped': 0,
            'setpoints_stale': 0}


@dataclass
class ControllerState:
    """The simulated controller's shared state (all SI: m, m/s^2; ticks and sequences in samples)."""

    state: str = 'idle'             # STATES name: idle, running, holding, ramping_down, fault
    fault_bits: int = 0             # FAULT_* bits latched until RESET
    ticks: int = 0                  # ticks since start = rig time * fs
    next_seq: int = 0               # full sequence of the next tick
    buffer: dict = field(default_factory=dict)   # seq -> setpoint [m] queued
    u: float = 0.0                  # applied command [m]
    u_prev: float = 0.0             # the one before [m]
    # setpoints start a stream from idle only at or after this sample (HostStreamStart); after a ramp to rest none
    # until the host announces the next stream (CTRL-PWR-1: from power-up, none before a HostStreamStart)
    accept_from: float = math.inf
    last_host_hb: int = 0           # tick of the last HostHeartbeat (the host watchdog, CTRL-WD-1)
    # the host's limits for the controller's own ramps (HostLimits frame); until then: no bounds
    lower: float = -math.inf
    upper: float = math.inf
    decel_max: float = DECEL_MAX
    counters: dict = field(default_factory=_counters)
