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

"""CPU used by the suite's processes and by the rest of the machine over a run, read from /proc (Linux).

A performance figure means little without its conditions: the same run takes longer and wakes later when other
programs share the cores. :class:`CpuMeter` takes two snapshots (start, end) and reports, per watched process, the
CPU it used (utime + stime of ``/proc/<pid>/stat``, all its threads) as a fraction of one core over the wall time
of the run; the CPU the whole machine used (``/proc/stat``, all cores, idle and iowait left out) and therefore what
everything else used; the 1-minute load average at start and end (``/proc/loadavg``). A run during which the
others used more than :data:`UNDER_LOAD` of a core is flagged as measured under load.

Wake-ups: a node's executor spins in a thread named ``executor`` (nodes/spin.py). Each time that thread blocks,
waiting for work, the kernel counts a voluntary context switch (``/proc/<pid>/task/<tid>/status``), so its CPU time
divided by those switches is the CPU per wake-up (an upper bound: a wake-up that finds more work queued does not
block in between, and one that waits for the interpreter lock counts twice). Cheap enough to read at any time,
and no node code is involved in counting.
"""
from __future__ import annotations

import cProfile
import ctypes
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

PROC = Path('/proc')
CLOCK_TICKS = os.sysconf('SC_CLK_TCK') if hasattr(os, 'sysconf') else 100   # jiffies per second
UNDER_LOAD = 0.1          # [cores] CPU used by other programs over a run above which its figures are "under load"
EXECUTOR_THREAD = 'executor'   # the thread name nodes/spin.py gives the thread that spins a node's executor
RECEIVE_THREAD = 'can-receive'   # rig_driver's thread that reads the bus (receive: thread, rig.can.receiver)


def name_this_thread(name: str) -> None:
    """Give the calling thread an OS name (``top -H``, ``ps -L`` and :func:`executor_thread` see it; 15 bytes)."""
    try:
        ctypes.CDLL(None).prctl(15, name.encode()[:15], 0, 0, 0)   # PR_SET_NAME: the calling thread
    except (OSError, AttributeError):   # not Linux: the thread keeps its name, wake-ups are not counted
        pass


PROFILE_ENV = 'RUBBER_RIG_PROFILE_DIR'   # set: each node's executor thread runs under cProfile (run_profiled)


def run_profiled(fn, name: str) -> None:
    """``fn()``; under cProfile when the environment names a directory in PROFILE_ENV, the statistics then written
    to ``<dir>/<name>-<pid>.prof`` when it returns (read them with ``python -m pstats``). Where a node's CPU goes,
    without py-spy: ``RUBBER_RIG_PROFILE_DIR=/tmp/prof rubber-rig bench``. Wall time: on a busy machine a function
    preempted half way is charged the wait; cProfile slows what it profiles (a paced program may run out of
    setpoints): its call counts and shares count, not its times.
    """
    where = os.environ.get(PROFILE_ENV)
    if not where:
        fn()
        return
    profile = cProfile.Profile()   # wall time (a CPU-time timer is a system call per event: too slow to keep up)
    try:
        profile.runcall(fn)
    finally:
        Path(where).mkdir(parents=True, exist_ok=True)
        profile.dump_stats(str(Path(where) / f'{name.strip("/").replace("/", "_") or "node"}-{os.getpid()}.prof'))


def process_cpu(pid: int) -> float:
    """CPU time [s] (user + system, all threads) process `pid` has used so far; NaN once it is gone."""
    return _stat_cpu(PROC / str(pid) / 'stat')


def _stat_cpu(path: Path) -> float:
    try:
        text = path.read_text()
    except OSError:
        return float('nan')
    fields = text[text.rindex(')') + 2:].split()   # after "pid (comm) ": comm may hold spaces
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS   # fields 14 and 15 of proc(5): utime, stime


def child_pids(pid: int) -> list[int]:
    """Process ids whose parent is `pid` (e.g. the simulated rig that rig_driver started with spawn_sim)."""
    children = []
    for entry in PROC.iterdir():
        if entry.name.isdigit():
            try:
                text = (entry / 'stat').read_text()
            except OSError:
                continue
            if int(text[text.rindex(')') + 2:].split()[1]) == pid:
                children.append(int(entry.name))
    return sorted(children)


def executor_thread(pid: int) -> int | None:
    """Thread id of the node's executor thread in process `pid` (named by nodes/spin.py), or None."""
    try:
        for task in (PROC / str(pid) / 'task').iterdir():
            if (task / 'comm').read_text().strip() == EXECUTOR_THREAD:
                return int(task.name)
    except OSError:
        pass
    return None


def thread_cpu_and_waits(pid: int, tid: int) -> tuple[float, int]:
    """(CPU time [s], voluntary context switches) of thread `tid` of process `pid`; (NaN, -1) once it is gone."""
    task = PROC / str(pid) / 'task' / str(tid)
    cpu = _stat_cpu(task / 'stat')
    try:
        for line in (task / 'status').read_text().splitlines():
            if line.startswith('voluntary_ctxt_switches:'):
                return cpu, int(line.split()[1])
    except OSError:
        pass
    return cpu, -1


def machine_cpu() -> tuple[float, float]:
    """(busy, total) CPU time [s] of all cores since boot: /proc/stat's first line, busy without idle and iowait."""
    try:
        values = [int(v) for v in (PROC / 'stat').read_text().splitlines()[0].split()[1:9]]
    except (OSError, ValueError, IndexError):
        return float('nan'), float('nan')
    total = sum(values)          # user nice system idle iowait irq softirq steal (guest is inside user)
    return (total - values[3] - values[4]) / CLOCK_TICKS, total / CLOCK_TICKS


def load_average() -> float:
    """The 1-minute load average (runnable and uninterruptible tasks, all cores)."""
    try:
        return float((PROC / 'loadavg').read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return float('nan')


@dataclass
class ProcessUse:
    """What one watched process used over the run."""

    name: str
    pid: int
    cores: float                  # CPU time / wall time [cores]: 1.0 is one core busy all the time
    wakeups: int = -1             # voluntary context switches of its executor thread (-1: no such thread)
    executor_cores: float = float('nan')   # the executor thread's share of `cores`

    @property
    def cpu_per_wakeup_us(self) -> float:
        """Executor-thread CPU per wake-up [us] (upper bound: see the module's docstring)."""
        return self.executor_cores * self._wall / self.wakeups * 1e6 if self.wakeups > 0 else float('nan')

    _wall: float = field(default=0.0, repr=False)

    def as_dict(self) -> dict:
        return {'pid': self.pid, 'cpu_cores': self.cores, 'executor_wakeups': self.wakeups,
                'executor_wakeups_per_s': self.wakeups / self._wall if self.wakeups >= 0 and self._wall else None,
                'executor_cpu_cores': self.executor_cores, 'cpu_per_wakeup_us': self.cpu_per_wakeup_us}


@dataclass
class CpuReport:
    """The CPU side of a run: per process, the machine, and whether it ran under load."""

    wall_time: float                                  # [s]
    processes: list[ProcessUse]
    machine_cores: float                              # [cores] used by the whole machine over the run
    cores: int                                        # cores the machine has
    load_start: float                                 # 1-minute load average at start and at end
    load_end: float

    @property
    def watched_cores(self) -> float:
        return sum(p.cores for p in self.processes if p.cores == p.cores)

    @property
    def other_cores(self) -> float:
        """[cores] used by everything else on the machine over the run (never below 0: counters tick apart)."""
        return max(0.0, self.machine_cores - self.watched_cores)

    @property
    def under_load(self) -> bool:
        return self.other_cores > UNDER_LOAD

    def as_dict(self) -> dict:
        return {'wall_time_s': self.wall_time, 'processes': {p.name: p.as_dict() for p in self.processes},
                'watched_cores': self.watched_cores, 'machine_cores_used': self.machine_cores,
                'other_cores_used': self.other_cores, 'cores': self.cores, 'load_average_1min_start': self.load_start,
                'load_average_1min_end': self.load_end, 'under_load': self.under_load,
                'under_load_threshold_cores': UNDER_LOAD}

    def lines(self) -> list[str]:
        """The report for a terminal: one line per process, then the machine's."""
        out = []
        for p in self.processes:
            wake = (f', {p.wakeups / self.wall_time:.0f} wake-ups/s, {p.cpu_per_wakeup_us:.0f} us CPU per wake-up'
                    if p.wakeups > 0 and self.wall_time > 0 else '')
            out.append(f'  {p.name:<14} {p.cores * 100:5.1f} % of a core{wake}')
        out.append(f'  machine: {self.cores} cores, {self.machine_cores * 100:.0f} % of a core used in all, '
                   f'{self.other_cores * 100:.0f} % by other programs; load average (1 min) '
                   f'{self.load_start:.2f} at start, {self.load_end:.2f} at end')
        if self.under_load:
            out.append(f'  MEASURED UNDER LOAD: other programs used {self.other_cores:.2f} cores during the run '
                       f'(more than {UNDER_LOAD:g}): these figures are not those of a quiet machine')
        return out


class CpuMeter:
    """Snapshots of the watched processes and the machine at :meth:`start` and :meth:`stop`.

    ``processes``: {name: pid}; a process that ends before the stop reports NaN.
    """

    def __init__(self, processes: dict[str, int]):
        self.pids = dict(processes)
        self._start = None

    def _snapshot(self) -> dict:
        procs = {}
        for name, pid in self.pids.items():
            tid = executor_thread(pid)
            thread = thread_cpu_and_waits(pid, tid) if tid is not None else (float('nan'), -1)
            procs[name] = (process_cpu(pid), thread)
        return {'time': time.monotonic(), 'machine': machine_cpu(), 'load': load_average(), 'procs': procs}

    def start(self) -> 'CpuMeter':
        self._start = self._snapshot()
        return self

    def stop(self) -> CpuReport:
        if self._start is None:
            raise RuntimeError('CpuMeter.stop() before start()')
        a, b = self._start, self._snapshot()
        wall = max(b['time'] - a['time'], 1e-9)
        uses = []
        for name, pid in self.pids.items():
            (cpu0, (tcpu0, waits0)), (cpu1, (tcpu1, waits1)) = a['procs'][name], b['procs'][name]
            waits = waits1 - waits0 if waits0 >= 0 and waits1 >= 0 else -1
            uses.append(ProcessUse(name, pid, (cpu1 - cpu0) / wall, waits, (tcpu1 - tcpu0) / wall, _wall=wall))
        return CpuReport(wall, uses, (b['machine'][0] - a['machine'][0]) / wall, os.cpu_count() or 1,
                         a['load'], b['load'])
