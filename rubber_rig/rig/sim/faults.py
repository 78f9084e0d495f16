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

"""Fault injection on the simulated controller's transmit path and sensors (seeded, so runs repeat)."""
import numpy as np


class FaultInjector:
    """Applies the configured FaultSpecs to each outgoing frame at rig time t [s].

    transmit() returns the list of (extra_delay_ticks, message) to put on the bus: [] for a dropped frame,
    two entries for a duplicated one, a bit-flipped payload for a corrupted one (its CRC no longer matches).
    """

    def __init__(self, faults, sample_rate: float, seed: int):
        self.faults = list(faults)
        self.fs = sample_rate
        self.rng = np.random.default_rng(seed + 7919)

    def silent(self, t: float) -> bool:
        """True while a silent-controller fault suppresses heartbeat and status."""
        return any(f.type == 'silent_controller' and f.active(t) for f in self.faults)

    def stuck(self, t: float):
        """Names of the sensors stuck at time t."""
        return {f.sensor for f in self.faults if f.type == 'stuck_sensor' and f.active(t)}

    def transmit(self, name: str, msg, t: float):
        out = [(0, msg)]
        if name in ('ControllerHeartbeat', 'ControllerStatus', 'ControllerIdentity') and self.silent(t):
            return []
        for f in self.faults:
            if f.type in ('stuck_sensor', 'silent_controller', 'bus_flood') or name not in f.frames \
                    or not f.active(t):
                continue
            if f.probability < 1.0 and self.rng.random() >= f.probability:
                continue
            if f.type == 'drop':
                return []
            if f.type == 'duplicate':
                out = out + [(d, m) for d, m in out]
            elif f.type == 'delay':
                out = [(d + max(1, round(f.delay * self.fs)), m) for d, m in out]
            elif f.type == 'corrupt':
                data = bytearray(msg.data)
                bit = int(self.rng.integers(0, 8 * (len(data) - 1)))
                data[bit // 8] ^= 1 << (bit % 8)
                msg.data = data
        return out
