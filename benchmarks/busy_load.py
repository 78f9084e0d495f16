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

"""Run a command while busy loops load the CPU cores (does the test suite pass on a busy computer?).

    .venv/bin/python benchmarks/busy_load.py -- make test              # one busy loop per core, one run
    .venv/bin/python benchmarks/busy_load.py --runs 3 -- make test     # three consecutive runs (issue 34)
    make test-under-load                                               # the same as the line above
    .venv/bin/python benchmarks/busy_load.py --loops 1 -- .venv/bin/python benchmarks/bench_soak.py ...

Each busy loop is a process of its own spinning on arithmetic at normal priority, like a compiler or a browser
tab beside the tests. The loops start before the first run and are stopped (by their process ids) after the last
one, also on Ctrl-C. Prints per run: exit status and wall time, then the load average; exits with the first
non-zero exit status of the runs (0 when all passed).
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # the command (tests, benchmarks) inherits the default
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking")

import argparse  # noqa: E402
import multiprocessing  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402


def spin(stop) -> None:
    """Busy-loop until `stop` is set (checked every few million operations)."""
    x = 0
    while not stop.is_set():
        for i in range(2_000_000):
            x = (x * 31 + i) & 0xFFFF


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--loops', type=int, default=os.cpu_count() or 2,
                        help='busy-loop processes (default: one per core, %(default)s here)')
    parser.add_argument('--runs', type=int, default=1, help='consecutive runs of the command (default 1)')
    parser.add_argument('command', nargs=argparse.REMAINDER, help='the command, after --')
    args = parser.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ['--'] else args.command
    if not command:
        parser.error('give the command to run after --, e.g. busy_load.py -- make test')
    stop = multiprocessing.Event()
    loops = [multiprocessing.Process(target=spin, args=(stop,), daemon=True) for _ in range(args.loops)]
    for p in loops:
        p.start()
    print(f'{args.loops} busy loops running (pids {", ".join(str(p.pid) for p in loops)}); '
          f'{args.runs} run(s) of: {" ".join(command)}', flush=True)
    status, results = 0, []
    try:
        for run in range(1, args.runs + 1):
            t0 = time.monotonic()
            rc = subprocess.call(command)
            took = time.monotonic() - t0
            results.append((run, rc, took))
            print(f'run {run}: exit status {rc}, {took:.0f} s, load average {os.getloadavg()[0]:.1f}', flush=True)
            status = status or rc
    finally:
        stop.set()
        for p in loops:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()
    passed = sum(1 for _, rc, _ in results if rc == 0)
    print(f'{passed} of {len(results)} runs passed with {args.loops} busy loops; wall time per run: '
          + ', '.join(f'{took:.0f} s' for _, _, took in results))
    return status


if __name__ == '__main__':
    sys.exit(main())
