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

"""Stuck-sensor detection of the host driver (a fault the controller cannot see: its sensors look alive)."""


class SensorCheck:
    """Stuck-sensor detection from consistency, not from motion per window, so slow motion is covered too.

    A live transducer never repeats the same reading for 0.1 s while what drives it moves: the displacement
    is stuck when it repeats while the command moves >= 10 um, the load cell when it repeats while the
    measured displacement moves >= 5 um. And over any stretch of at least 0.1 s where the command spans >= 50 um,
    the measured displacement must span at least 10 % of it (the actuator attenuates, it does not stop). The
    stretch is never shorter than 0.1 s because the actuator lags: at 50 Hz and 1 kHz the command moves 0.12 mm
    in two samples while a lagging actuator turns at its peak and moves 0.01 mm; over 0.1 s it has followed.
    """

    def __init__(self, fs):
        self.n_same = max(10, int(round(0.1 * fs)))
        self.window_max = max(10, int(round(2.0 * fs)))
        self.clear()

    def clear(self):
        self.x_prev = self.f_prev = None
        self.x_run = self.f_run = 0
        self.u_lo = self.u_hi = self.x_lo = self.x_hi = None        # during the current repeated x / f
        self.wu_lo = self.wu_hi = self.wx_lo = self.wx_hi = None    # consistency window
        self.wn = 0

    def add(self, u, x, f) -> str:
        if x == self.x_prev:
            self.x_run += 1
            self.u_lo, self.u_hi = min(self.u_lo, u), max(self.u_hi, u)
        else:
            self.x_run, self.u_lo, self.u_hi = 0, u, u
        if f == self.f_prev:
            self.f_run += 1
            self.x_lo, self.x_hi = min(self.x_lo, x), max(self.x_hi, x)
        else:
            self.f_run, self.x_lo, self.x_hi = 0, x, x
        self.x_prev, self.f_prev = x, f
        if self.x_run >= self.n_same and self.u_hi - self.u_lo >= 10e-6:
            return (f'displacement sensor stuck at {x * 1e3:.4f} mm for {self.x_run} samples while the command '
                    f'moved {(self.u_hi - self.u_lo) * 1e3:.4f} mm')
        if self.f_run >= self.n_same and self.x_hi - self.x_lo >= 5e-6:
            return (f'force sensor stuck at {f:.2f} N for {self.f_run} samples while the displacement moved '
                    f'{(self.x_hi - self.x_lo) * 1e3:.4f} mm')
        if self.wn == 0:
            self.wu_lo = self.wu_hi = u
            self.wx_lo = self.wx_hi = x
        self.wn += 1
        self.wu_lo, self.wu_hi = min(self.wu_lo, u), max(self.wu_hi, u)
        self.wx_lo, self.wx_hi = min(self.wx_lo, x), max(self.wx_hi, x)
        du = self.wu_hi - self.wu_lo
        if du >= 50e-6 and self.wn >= self.n_same:
            dx = self.wx_hi - self.wx_lo
            self.wn = 0
            if dx < 0.1 * du:
                return (f'displacement sensor stuck or disconnected: the command moved {du * 1e3:.4f} mm, the '
                        f'measurement {dx * 1e3:.4f} mm')
        elif self.wn >= self.window_max:
            self.wn = 0
        return ''
