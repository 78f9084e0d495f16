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

"""The kernel's own account of this host's lateness: how long a process of this host (the simulator with
``conformance --sim``) was ready to run but waited for a CPU, and how many frames the run's socket dropped
(docs/protocol.md, "Host timing").

Linux counts, per task, the time it spent runnable on a run-queue without running: the second field of
/proc/<pid>/task/<tid>/schedstat, in ns (CONFIG_SCHED_INFO; 0 where the kernel does not account it). A simulator
that waited X ms there sent its frames X ms late because this host gave its CPUs to others; a controller with a
CPU of its own would not have. This catches what the simulator's own deadline log cannot: a wait between its
deadline check and its send, or across a wake-up that started a stream. The conformance run samples the waits
every few ms (RunQueueWatch) and adds each increase of RUN_QUEUE_MIN or more as a lateness window; with it the
drops of its own udp_multicast socket (can.udp_socket), each increase a window since the previous sample.

Linux's pressure stall information (/proc/pressure/cpu, ``some``: the time at least one task of the host waited)
is reported with the run as context (cpu_pressure) but never used to excuse a verdict: with a busy loop per core
it is near 100 % all the time, so it cannot tell whether the controller's process was the one kept waiting.
"""
from __future__ import annotations

import glob

from ..can.udp_socket import dropped, socket_inode
from .host_timing import DropWatch

RUN_QUEUE_MIN = 0.002    # [s] a run-queue wait this long (within one sampling interval) is recorded: as the
#                         simulator's own missed deadlines (host_timing.SIM_LATE_MIN)
SAMPLE_PERIOD = 0.005    # [s] the waits are read at most this often (a read costs ~20 us per task)
PSI_CPU = '/proc/pressure/cpu'
OWN_WAITS = 'run-queue waits of this run'   # host_timing source: the conformance run's own process


def read_waits(pids) -> dict:
    """{(pid, tid): cumulative run-queue wait [s]} of every task (thread) of the processes `pids`; a process or
    task that is gone or unreadable is left out (never an error: the run goes on without that source).
    """
    waits = {}
    for pid in pids:
        for path in glob.glob(f'/proc/{int(pid)}/task/*/schedstat'):
            try:
                with open(path, encoding='ascii') as f:
                    fields = f.read().split()
                waits[(int(pid), int(path.split('/')[-2]))] = int(fields[1]) * 1e-9
            except (OSError, ValueError, IndexError):
                continue
    return waits


class RunQueueWatch:
    """Lateness windows (start, end) [s] from successive samples of cumulative run-queue waits.

    update(now, waits) takes the time of a sample [s] (the time base of the trace, time.time()) and {task:
    cumulative wait [s]} (read_waits); a task whose wait grew by RUN_QUEUE_MIN or more since its previous sample
    gives a window of that length ending at `now`, clipped to the previous sample: a task woken on time usually
    waits right before it runs, which is when it was sampled next. The window then says "this host held this
    task back for that long, in this interval", never more than the kernel counted.
    """

    def __init__(self, late_min: float = RUN_QUEUE_MIN):
        self.late_min = float(late_min)
        self._last = {}           # task -> (time of its previous sample [s], cumulative wait then [s])

    def update(self, now: float, waits: dict) -> list:
        windows = []
        for task, wait in waits.items():
            previous = self._last.get(task)
            self._last[task] = (now, wait)
            if previous is None:        # a task seen for the first time: its wait so far is no window
                continue
            t_prev, wait_prev = previous
            grew = wait - wait_prev
            if grew >= self.late_min:
                windows.append((max(t_prev, now - grew), now))
        return windows


def cpu_pressure(path: str = PSI_CPU):
    """Cumulative time [s] at least one task of this host waited for a CPU (PSI cpu ``some`` total), None where
    the kernel has no pressure stall information.
    """
    try:
        with open(path, encoding='ascii') as f:
            first = f.readline().split()
        return int(dict(field.split('=') for field in first[1:])['total']) * 1e-6
    except (OSError, ValueError, KeyError, IndexError):
        return None


def pressure_share(before, after, seconds: float):
    """The share (0..1) of `seconds` of the run that some task of this host waited for a CPU, from two
    cpu_pressure readings; None when either is missing or the run took no time.
    """
    if before is None or after is None or seconds <= 0:
        return None
    return min(max((after - before) / seconds, 0.0), 1.0)


class KernelCounts:
    """What the kernel counted of this host's lateness during a run on the wall clock, into `timing` (a
    host_timing.HostTiming): the run-queue waits of the processes `pids` (the simulator's, added when it starts)
    and of the run's own process `own_pid`, and the drops of the socket under `bus` (None: no socket watched).
    sample(now) is called by the run's receive loop; it reads at most every SAMPLE_PERIOD.
    """

    def __init__(self, timing, bus=None, own_pid=None):
        self.timing, self.pids = timing, []
        self._waits, self._drops, self._next = RunQueueWatch(), DropWatch(), 0.0
        self._socket = socket_inode(bus) if bus is not None else None
        # this run's own process (None: not watched): its scenario and receive threads kept from a CPU saw and
        # sent late - a stale view of the controller, a stream sent late (host_excuse)
        self.own_pid, self._own = own_pid, RunQueueWatch()

    def sample(self, now: float):
        if now < self._next:
            return
        self._next = now + SAMPLE_PERIOD
        if self.pids:
            for t0, t1 in self._waits.update(now, read_waits(self.pids)):
                self.timing.add(t0, t1, 'run-queue waits of the simulator')
        if self.own_pid is not None:
            for t0, t1 in self._own.update(now, read_waits([self.own_pid])):
                self.timing.add(t0, t1, OWN_WAITS)
        if self._socket is not None:
            lost = self._drops.update(now, dropped(self._socket))
            if lost:
                self.timing.add(*lost, "frames dropped by this run's socket")
