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


"""`rubber-rig bench` (what `make bench` runs) as a user runs it, timed from outside: latency and CPU with their load.

    .venv/bin/python benchmarks/bench_main_job.py                                   # this checkout, 2 runs
    .venv/bin/python benchmarks/bench_main_job.py --against /tmp/old --runs 3       # old and new back to back
    .venv/bin/python benchmarks/bench_main_job.py --modes processes,in-process      # the two ways of starting

Each run is the shipped program (dynamic_stiffness_grid, 116 s of paced excitation at 1 kHz unless ARGS say
otherwise) started as its own `python -m rubber_rig.cli.main bench` process with the checkout's code on PYTHONPATH.
While its program runs (from its 'recording to' line to its 'program:' line) this script meters, from /proc, the
bench process and every process below it (node processes, the simulated rig's), named by their command lines, and
the machine (rubber_rig.cpu): CPU as % of one core, the CPU every other program used meanwhile, the load average at
start and end. A node process is metered up to its last reading (every 0.5 s) before the bench stops it: the
figures include the few seconds after the program (catch-up, closing the recording). Latency (sample taken ->
prediction at the bench's monitor, first and last sample of a batch) comes from the run's summary JSON.
`--against DIR` alternates with the runs of another checkout (git worktree add DIR COMMIT), whose own `rubber-rig
bench` runs as it did then (older ones: every node a thread of one process), so both see the same machine, minutes
apart. A figure measured while other programs used more than 0.1 core says so.
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
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))      # rubber_rig.cpu of this checkout, whichever checkout is being measured
from rubber_rig.cpu import CpuReport, ProcessUse, child_pids, load_average, machine_cpu, process_cpu  # noqa: E402

SAMPLE_PERIOD = 0.5     # [s] /proc is read this often: a node process's figure ends with its last reading

NAMES = {'rubber_rig.nodes.rig_driver_node': 'rig_driver', 'rubber_rig.nodes.excitation_node': 'excitation',
         'rubber_rig.nodes.element_model_node': 'element_model', 'rubber_rig.nodes.recorder_node': 'recorder',
         'rubber_rig.rig.sim': 'sim_rig', 'rubber_rig.nodes.foxglove_view_node': 'foxglove_view'}
NODES = ('rig_driver', 'excitation', 'element_model', 'recorder')


def process_tree(pid: int) -> dict:
    """{name: pid} of the bench process and every process below it, named by the module each runs."""
    tree, todo = {}, [pid]
    while todo:
        p = todo.pop()
        try:
            cmd = Path(f'/proc/{p}/cmdline').read_bytes().split(b'\0')
        except OSError:
            continue
        words = [w.decode(errors='replace') for w in cmd]
        name = next((NAMES[w] for w in words if w in NAMES), 'bench' if p == pid else f'pid{p}')
        tree[name if name not in tree else f'{name}_{p}'] = p
        todo += child_pids(p)
    return tree


class TreeMeter:
    """CPU of a process tree and of the machine from start() until stop(), read every SAMPLE_PERIOD: a process
    that ends before the stop (the bench stops its nodes before it prints its result) counts up to its last
    reading, over its own time.
    """

    def __init__(self, tree: dict):
        self.tree = tree
        self._stop = threading.Event()
        now = time.monotonic()
        self.t0, self.machine0, self.load0 = now, machine_cpu()[0], load_average()
        self.cpu0 = {name: process_cpu(pid) for name, pid in tree.items()}
        self.last = {name: (c, now) for name, c in self.cpu0.items()}
        self.machine_last = (self.machine0, now)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        now = time.monotonic()
        for name, pid in self.tree.items():
            c = process_cpu(pid)
            if c == c:
                self.last[name] = (c, now)
        self.machine_last = (machine_cpu()[0], now)

    def _run(self) -> None:
        while not self._stop.wait(SAMPLE_PERIOD):
            self._read()

    def stop(self) -> CpuReport:
        self._stop.set()
        self._thread.join()
        self._read()
        wall = self.machine_last[1] - self.t0
        uses = []
        for name, pid in self.tree.items():
            c, t = self.last[name]
            own = max(t - self.t0, 1e-9)
            uses.append(ProcessUse(name, pid, (c - self.cpu0[name]) / own, _wall=own))
        return CpuReport(wall, uses, (self.machine_last[0] - self.machine0) / wall, os.cpu_count() or 1, self.load0,
                         load_average())


def run_bench(checkout: Path, label: str, mode: str, bench_args: list, domain: int, out: Path) -> dict:
    """One `rubber-rig bench` of `checkout`, metered while its program runs."""
    env = dict(os.environ, PYTHONPATH=str(checkout), ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1')
    env.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    cmd = [sys.executable, '-m', 'rubber_rig.cli.main', 'bench', '--quiet', '--output-dir', str(out),
           '--domain-id', str(domain), *bench_args] + (['--in-process'] if mode == 'in-process' else [])
    proc = subprocess.Popen(cmd, cwd=checkout, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    meter, cpu, lines = None, None, []
    for line in proc.stdout:
        lines.append(line.rstrip())
        if line.startswith('recording to ') and meter is None:
            meter = TreeMeter(process_tree(proc.pid))
        elif line.startswith('program: ') and meter is not None and cpu is None:
            cpu = meter.stop()
    rc = proc.wait()
    summary_path = next((ln.split('summary:', 1)[1].strip() for ln in lines if ln.startswith('summary:')), '')
    summary = json.loads(Path(summary_path).read_text()) if summary_path.endswith('.json') else {}
    for mcap in out.rglob('*.mcap'):           # the figures are in the summary; the recordings are not kept
        mcap.unlink()
    return {'label': label, 'mode': mode, 'checkout': str(checkout), 'exit_status': rc,
            'program': next((ln[len('program: '):] for ln in lines if ln.startswith('program: ')), 'no result'),
            'latency': summary.get('latency', {}), 'loss': summary.get('loss', {}).get('live', {}),
            'cpu': cpu.as_dict() if cpu else None, 'cpu_lines': cpu.lines() if cpu else [],
            'output_tail': lines[-12:] if rc else []}


def row(r: dict) -> str:
    lat, first = r['latency'].get('last_sample', {}), r['latency'].get('first_sample', {})
    cpu = r['cpu'] or {'processes': {}, 'other_cores_used': float('nan'), 'under_load': False,
                       'load_average_1min_start': float('nan')}
    procs = cpu['processes']
    nodes = [procs[n]['cpu_cores'] for n in NODES if n in procs]
    node_cores = sum(nodes) if len(nodes) == len(NODES) else procs.get('bench', {}).get('cpu_cores', float('nan'))
    per_node = ' / '.join(f"{procs[n]['cpu_cores'] * 100:.0f}" for n in NODES if n in procs) or 'one process'
    sim = procs.get('sim_rig', {}).get('cpu_cores')
    gaps = sum(v.get('gaps', 0) for v in r['loss'].values())
    ok = r['program'].startswith('completed')
    return (f"| {r['label']} | {r['mode']} | {'completed' if ok else r['program'][:60]} | {gaps} | "
            f"{first.get('median_ms', float('nan')):.1f} / {first.get('p99_ms', float('nan')):.1f} | "
            f"{lat.get('median_ms', float('nan')):.1f} / {lat.get('p99_ms', float('nan')):.1f} | "
            f"{node_cores * 100:.0f} | {per_node} | {'-' if sim is None else f'{sim * 100:.0f}'} | "
            f"{cpu['other_cores_used'] * 100:.0f}{' UNDER LOAD' if cpu['under_load'] else ''} | "
            f"{cpu['load_average_1min_start']:.2f} |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--runs', type=int, default=2, help='runs per checkout and mode (default 2)')
    parser.add_argument('--against', help='another checkout (e.g. git worktree add /tmp/old 78de0c9) to run '
                        'back to back with this one')
    parser.add_argument('--modes', default='processes', help="this checkout's ways of starting the nodes, comma "
                        "separated: processes (the default of rubber-rig bench), in-process")
    parser.add_argument('--domain-id', type=int, default=None, help='ROS domain (default: a private one)')
    parser.add_argument('--json', help='also write the results to this JSON file')
    parser.add_argument('bench_args', nargs='*', help='arguments for rubber-rig bench after --, e.g. -- --blocks 5')
    args = parser.parse_args(argv)
    domain = args.domain_id if args.domain_id is not None else 150 + os.getpid() % 50
    plan = [(ROOT, 'this checkout', mode) for mode in args.modes.split(',')]
    if args.against:
        plan.append((Path(args.against).resolve(), f'{Path(args.against).name} (--against)', 'as it ran then'))
    results = []
    with tempfile.TemporaryDirectory(prefix='bench_main_job_') as tmp:
        for i in range(args.runs):
            for checkout, label, mode in plan:
                print(f'--- run {i + 1}/{args.runs}: {label}, {mode} ...', flush=True)
                r = run_bench(checkout, label, mode, args.bench_args, domain, Path(tmp))
                results.append(r)
                print(f"    {r['program'][:100]}", flush=True)
                for line in r['cpu_lines']:
                    print('  ' + line, flush=True)
                for line in r['output_tail']:
                    print('    | ' + line, flush=True)
    print('\n| checkout | nodes | program | gaps (live) | latency first sample median / p99 [ms] | '
          'last sample median / p99 [ms] | four nodes [% core] | rig_driver / excitation / element_model / '
          'recorder [% core] | sim rig [% core] | others on the machine [% core] | load avg at start |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    for r in results:
        print(row(r))
    print('\nfour nodes: the four node processes together; with every node in one process (in-process, older '
          'checkouts): that process, which also holds the monitor and, paced, the simulated rig')
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2, default=float))
    return 0 if all(r['exit_status'] == 0 for r in results) else 1


if __name__ == '__main__':
    sys.exit(main())
