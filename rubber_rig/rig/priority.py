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

"""The scheduling priority of the process that talks to the rig controller (rig_driver).

What moves the rig is rig_driver's data path: it reads the controller's feedback off the bus and hands the owner's
setpoints on to the controller, which plays them on its own clock. A computer that also runs Foxglove, a browser and
last night's fits delays that path, and the controller runs dry of setpoints the owner has long sent (seen on a
2-core machine with two busy loops: "the rig ran out of setpoints at sample 50"). ros2_control gives its control
loop a real-time priority for the same reason (controller_manager's thread_priority); here it is the process's
niceness, which needs no real-time kernel and cannot lock a core: a lower niceness gives the driver the CPU before
programs of the default niceness 0, and it still yields when idle.

On Linux niceness belongs to each thread, and the middleware's threads exist before the node reads its
parameters: every thread of the process is set, and threads started later inherit it from the one that starts them.
"""
from __future__ import annotations

import os

NICE_MIN, NICE_MAX = -20, 19


def set_process_nice(nice: int) -> str:
    """Give every thread of this process, and of the processes it has started, the niceness `nice` (-20..19; lower
    runs first; 0 is the default).

    Returns '' when done (or nothing to do), else why not: raising the priority (a niceness below the current one)
    needs root, CAP_SYS_NICE or a ``nice`` limit in /etc/security/limits.conf; the process then keeps its
    priority and runs as before.
    """
    nice = int(nice)
    if not NICE_MIN <= nice <= NICE_MAX:
        raise ValueError(f'niceness {nice}: outside {NICE_MIN}..{NICE_MAX}')
    threads = _threads(os.getpid()) or [0]
    # and the processes it started already (the simulated rig with spawn_sim, started by configure): the controller
    # they stand for has a CPU of its own
    for child in _children(os.getpid()):
        threads += _threads(child)
    current = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        for tid in threads:
            try:
                os.setpriority(os.PRIO_PROCESS, tid, nice)
            except ProcessLookupError:     # a thread that ended meanwhile
                pass
    except PermissionError:
        return (f'could not set the niceness to {nice} (raising the priority needs root, CAP_SYS_NICE or a "nice" '
                f'limit in /etc/security/limits.conf); the process keeps {current}')
    return ''


def _threads(pid: int) -> list:
    try:
        return [int(t) for t in os.listdir(f'/proc/{pid}/task')]
    except OSError:
        return []


def _children(pid: int) -> list:
    """The processes whose parent is `pid` (from /proc/<pid>/stat)."""
    out = []
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            try:
                with open(f'/proc/{entry}/stat') as f:
                    if int(f.read().rsplit(')', 1)[1].split()[1]) == pid:
                        out.append(int(entry))
            except (OSError, ValueError, IndexError):
                pass
    return out


def process_nice() -> int:
    """The niceness of the calling thread (inherited by the threads it starts)."""
    return os.getpriority(os.PRIO_PROCESS, 0)
