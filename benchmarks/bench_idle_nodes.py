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

"""What the four nodes cost at rest: CPU, executor wake-ups and CPU per wake-up of each node process (issue 37).

    .venv/bin/python benchmarks/bench_idle_nodes.py                               # this checkout, 2 rounds
    .venv/bin/python benchmarks/bench_idle_nodes.py --against /tmp/old --rounds 3 # another checkout back to back

rig_driver, excitation, element_model and recorder, each a process of its own started as ``ros2 launch`` starts
them (``python -m rubber_rig.nodes.<node>_node`` with config/rig_sim.yaml: rig_driver with its paced simulated rig
in its process, idle), no program running. Once every node's executor thread is up (nodes/spin.py names it) and
a few seconds of start-up have passed, /proc is read at the start and end of a window (rubber_rig.cpu): CPU of the
process as % of one core, the executor thread's CPU, its wake-ups (voluntary context switches) per second and its
CPU per wake-up, and rig_driver's bus-reading thread (``can-receive``) apart. At rest a node does only its periodic
work (heartbeat, status, diagnostics, peer checks, the driver's bus reads): what its timers cost, which is what a
rig PC pays all day. ``--against DIR`` alternates with the same measurement of another checkout. A window during
which other programs used more than 0.1 core says so.
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from rubber_rig.cpu import (  # noqa: E402
    RECEIVE_THREAD,
    UNDER_LOAD,
    executor_thread,
    load_average,
    machine_cpu,
    process_cpu,
    thread_cpu_and_waits,
)

NODES = {'rig_driver': (), 'excitation': ('-p', 'require_recording:=false'), 'element_model': (), 'recorder': ()}
START_TIMEOUT = 90.0   # [s] for every executor thread to appear (a loaded machine starts slowly)
SETTLE = 8.0           # [s] after that, before the window opens (discovery, first statuses)


def named_thread(pid: int, name: str) -> int | None:
    try:
        for task in (Path('/proc') / str(pid) / 'task').iterdir():
            if (task / 'comm').read_text().strip() == name:
                return int(task.name)
    except OSError:
        pass
    return None


def snapshot(procs: dict) -> dict:
    out = {}
    for name, proc in procs.items():
        tid, rx = executor_thread(proc.pid), named_thread(proc.pid, RECEIVE_THREAD)
        cpu, waits = thread_cpu_and_waits(proc.pid, tid) if tid else (float('nan'), -1)
        rx_cpu = thread_cpu_and_waits(proc.pid, rx)[0] if rx else 0.0
        out[name] = (process_cpu(proc.pid), cpu, waits, rx_cpu)
    return out


def measure(checkout: Path, window: float, domain: int) -> dict:
    """The four nodes of `checkout` at rest over `window` s: per node and the machine's load."""
    env = dict(os.environ, PYTHONPATH=str(checkout), ROS_DOMAIN_ID=str(domain))
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    out_dir = tempfile.mkdtemp(prefix='bench_idle_nodes_')
    config = checkout / 'config' / 'rig_sim.yaml'
    procs = {name: subprocess.Popen(
        [sys.executable, '-m', f'rubber_rig.nodes.{name}_node', '--ros-args', '--params-file', str(config), *extra,
         *(('-p', f'output_dir:={out_dir}') if name == 'recorder' else ())],
        cwd=checkout, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)   # -m puts the cwd first
        for name, extra in NODES.items()}
    try:
        end = time.monotonic() + START_TIMEOUT
        while time.monotonic() < end and not all(executor_thread(p.pid) for p in procs.values()):
            time.sleep(0.5)
        time.sleep(SETTLE)
        a, m0, load0, t0 = snapshot(procs), machine_cpu(), load_average(), time.monotonic()
        time.sleep(window)
        b, m1, dt = snapshot(procs), machine_cpu(), time.monotonic() - t0
    finally:
        for p in procs.values():
            p.terminate()
        for p in procs.values():
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
    nodes = {}
    for name in NODES:
        cpu, ex, waits, rx = (b[name][i] - a[name][i] for i in range(4))
        nodes[name] = {'cpu_cores': cpu / dt, 'executor_cores': ex / dt, 'wakeups_per_s': waits / dt,
                       'cpu_per_wakeup_us': ex / waits * 1e6 if waits > 0 else float('nan'),
                       'receive_thread_cores': rx / dt}
    watched = sum(n['cpu_cores'] for n in nodes.values())
    others = (m1[0] - m0[0]) / dt - watched
    return {'checkout': str(checkout), 'window_s': dt, 'nodes': nodes, 'four_nodes_cores': watched,
            'other_cores': others, 'load_average_start': load0, 'under_load': others > UNDER_LOAD}


def lines(r: dict) -> list[str]:
    out = [f"{Path(r['checkout']).name}: four nodes at rest {r['four_nodes_cores'] * 100:.1f} % of a core "
           f"({r['window_s']:.0f} s; others {r['other_cores'] * 100:.0f} %, load average {r['load_average_start']:.2f}"
           + (', MEASURED UNDER LOAD)' if r['under_load'] else ')')]
    for name, n in r['nodes'].items():
        rx = f", can-receive thread {n['receive_thread_cores'] * 100:.1f} %" if n['receive_thread_cores'] else ''
        out.append(f"  {name:14} {n['cpu_cores'] * 100:5.1f} % of a core; executor {n['executor_cores'] * 100:5.1f} %, "
                   f"{n['wakeups_per_s']:6.1f} wake-ups/s, {n['cpu_per_wakeup_us']:5.0f} us CPU per wake-up{rx}")
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--rounds', type=int, default=2, help='measurements per checkout (default 2)')
    parser.add_argument('--window', type=float, default=30.0, help='seconds measured at rest (default 30)')
    parser.add_argument('--against', help='another checkout, measured alternately with this one')
    parser.add_argument('--domain-id', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', '0') or 0))
    parser.add_argument('--json', help='also write the results to this JSON file')
    args = parser.parse_args()
    checkouts = [ROOT] + ([Path(args.against).resolve()] if args.against else [])
    results = []
    for k in range(args.rounds):
        for checkout in checkouts:
            print(f'--- round {k + 1}/{args.rounds}: {checkout.name} ...', flush=True)
            results.append(measure(checkout, args.window, args.domain_id))
            print('\n'.join(lines(results[-1])), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
