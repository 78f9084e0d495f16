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

"""Safety figures of the node suite, each node in its own process (as ros2 launch starts them), paced at 1 kHz.

    .venv/bin/python benchmarks/bench_safety.py                 # 20 trials per path, 30 loaded programs
    .venv/bin/python benchmarks/bench_safety.py --trials 5 --programs 5 --json out.json
    .venv/bin/python benchmarks/bench_safety.py --paths "stream loss,watchdog" --stream-timeout 0.05 \
        --watchdog-timeout 0.06 --heartbeat-period 0.02      # the detection-time trade-off

1. Abort latency, from the request to the first ramp sample, for every way a program is stopped:
   excitation/abort, cancelling the goal, excitation/hold, rig_driver/abort, the setpoint stream lost (the
   excitation SIGKILLed) and the watchdog (the simulated controller's heartbeat and status frames go silent).
   The request time is the wall clock when the operator sent the request (or killed the process); for the
   watchdog it is the rig sample at which the controller falls silent. The first ramp sample is the first sample whose
   applied command is not the setpoint the program streamed for it, timed by the bus timestamp of its feedback
   frame (the same clock, this machine). For stream loss and the watchdog the driver must first notice the
   silence: their latency is reported in total and beyond the configured detection time (stream_timeout from
   the last batch, watchdog_timeout from the last heartbeat); --stream-timeout/--watchdog-timeout measure other
   settings (and their false trips).
2. False watchdog trips: programs run while two busy processes load both cores; every fault is counted.

The program is a 5 Hz, 1 mm sine (0.031 m/s peak) started at a random phase for each trial. Figures are printed
as markdown tables (and JSON with --json).
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
import argparse
import json
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from msg_defs.msg import RigStatus
from rubber_rig.testing.operator import Operator
from rubber_rig.testing.processes import SuiteProcesses

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'rig_sim.yaml'
NS = '/bench_safety'
FS = 1000.0
STREAM_TIMEOUT = 0.3          # rig_driver defaults (config/rig_sim.yaml), unless --stream-timeout etc.
WATCHDOG_TIMEOUT = 0.25
HEARTBEAT_SAMPLES = 50        # the simulated controller's heartbeat period (50 ms, DBC GenMsgCycleTime) at 1 kHz
SINE = """name: bench_safety
blocks:
  - {name: sine, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 150, taper_cycles: 1}
"""
SHORT = """name: bench_short
blocks:
  - {name: sine, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 10, taper_cycles: 1}
"""
PATHS = ('excitation abort', 'goal cancel', 'excitation hold', 'rig_driver abort', 'stream loss', 'watchdog')


class Bench:
    def __init__(self, base: Path, domain: int, driver_params: dict | None = None):
        self.base = base
        self.procs = SuiteProcesses(CONFIG, NS, domain, base / 'logs', {
            'rig_driver': dict(driver_params or {}),
            'recorder': {'output_dir': str(base / 'recordings')},
            'excitation': {'amplitude_control': False}})
        self.procs.start_all()
        self.op = Operator(NS, domain, name='bench_operator')
        if not self.op.wait_ready(60.0):
            raise SystemExit('the suite did not come up:\n' + self.procs.log('rig_driver')[-2000:])

    def close(self):
        self.op.close()
        self.procs.stop_all()

    # -- helpers
    def at_rest(self, timeout=10.0):
        """Wait until the rig is at rest (idle, holding or faulted, no ramp) and acknowledge a fault."""
        op = self.op
        ok = op.wait_status(lambda s: s.state in (RigStatus.STATE_IDLE, RigStatus.STATE_FAULT,
                                                  RigStatus.STATE_HOLDING) and not s.stream_owner, timeout)
        if op.status.state == RigStatus.STATE_FAULT:
            op.trigger('rig_driver/reset')
        return ok and op.wait_ready(20.0)

    def start_program(self, text=SINE):
        """Send the goal and wait until the program streams and has run 0.4..0.6 s (a random phase)."""
        op = self.op
        handle = op.send_goal(text, timeout=20.0)
        if handle is None or not handle.accepted:
            raise RuntimeError('goal not accepted')
        if not op.wait_status(lambda s: s.stream_owner == f'{NS}/excitation', 10.0):
            res = op.result(handle, 1.0)
            raise RuntimeError(f'program did not start: {res.message if res else "no result"}')
        first = op.status.next_sequence
        op.wait_for(lambda: op.last_sequence > first, 10.0)
        t_start = time.time()
        hold = random.uniform(0.4, 0.6)
        op.wait_for(lambda: time.time() - t_start > hold, hold + 1.0)
        return handle

    def departure_after(self, since, timeout=5.0):
        self.op.wait_for(lambda: self.op.first_departure(since) is not None, timeout, period=0.02)
        return self.op.first_departure(since)

    # -- one trial of each path: latency [s] from the request to the first ramp sample
    def operator_path(self, path):
        op = self.op
        handle = self.start_program()
        since = op.last_sequence + 1
        t_req = time.time()
        if path == 'excitation abort':
            r = op.trigger('excitation/abort')
            ok = r is not None and r.success
        elif path == 'goal cancel':
            ok = op.cancel(handle)
        elif path == 'excitation hold':
            r = op.hold(True)
            ok = r is not None and r.success
        elif path == 'rig_driver abort':
            r = op.trigger('rig_driver/abort')
            ok = r is not None and r.success
        else:
            raise ValueError(path)
        dep = self.departure_after(since)
        if path == 'excitation hold':   # held: wait for the hold to settle, then end the program
            op.wait_status(lambda s: s.state in (RigStatus.STATE_IDLE, RigStatus.STATE_HOLDING)
                           and s.stream_owner == f'{NS}/excitation', 5.0)
            op.trigger('excitation/abort')
        op.result(handle, 5.0)
        self.at_rest()
        if not ok or dep is None:
            raise RuntimeError(f'{path}: request failed or no ramp seen')
        return dep[1] - t_req

    def stream_loss(self):
        op, procs = self.op, self.procs
        self.start_program()
        since = op.last_sequence + 1
        t_req = time.time()
        procs.kill('excitation', signal.SIGKILL)
        dep = self.departure_after(since)
        self.at_rest()
        procs.start('excitation')
        if not procs.wait_started('excitation'):
            raise RuntimeError('excitation did not restart')
        if dep is None:
            raise RuntimeError('stream loss: no ramp seen')
        return dep[1] - t_req

    def watchdog(self, start, timeout):
        """The driver restarted with the controller's heartbeat falling silent at rig time `start` [s] of the first
        program after the restart (the fault clock counts idle time only after the first tick, so the silence
        begins at sample start * FS). Returns (latency from the silence, latency beyond the detection time) [s]:
        the driver detects `timeout` after the last heartbeat, which the controller sends every 50 samples, so
        0-50 ms before the silence.
        """
        op, procs = self.op, self.procs
        procs.stop('rig_driver')
        op.clear_history()          # the restarted rig counts samples from 0 again
        procs.start('rig_driver', {'sim': {'faults': f"[{{type: silent_controller, start: {start}, duration: 0.35}}]"}})
        if not procs.wait_started('rig_driver') or not op.wait_for(
                lambda: op.status is not None and op.status.state == RigStatus.STATE_IDLE
                and op.status.next_sequence == 0, 30.0):
            raise RuntimeError('rig_driver did not restart')
        handle = op.send_goal(SINE, timeout=20.0)
        silence = int(round(start * FS))
        dep = self.departure_after(silence - 1, timeout=start + 10.0)
        op.result(handle, 5.0)
        self.at_rest()
        if dep is None:
            raise RuntimeError('watchdog: no ramp seen')
        last_heartbeat = (silence - 1) // HEARTBEAT_SAMPLES * HEARTBEAT_SAMPLES
        return (dep[0] - silence) / FS, (dep[0] - last_heartbeat) / FS - timeout


def stats(values_ms):
    a = np.asarray(values_ms)
    return {'n': int(a.size), 'median_ms': float(np.median(a)), 'max_ms': float(np.max(a)),
            'min_ms': float(np.min(a))}


def latency_table(results):
    lines = ['| path | trials | median [ms] | max [ms] | detection [ms] | beyond detection: median / max [ms] |',
             '| --- | --- | --- | --- | --- | --- |']
    for path, r in results.items():
        det = r.get('detection_ms')
        if 'beyond_ms' in r:      # per trial (the watchdog: counted from the last heartbeat)
            beyond = f"{r['beyond_ms']['median_ms']:.0f} / {r['beyond_ms']['max_ms']:.0f}"
        else:
            beyond = f"{r['median_ms'] - det:.0f} / {r['max_ms'] - det:.0f}" if det else '-'
        lines.append(f"| {path} | {r['n']} | {r['median_ms']:.0f} | {r['max_ms']:.0f} | "
                     f"{det if det else '-'} | {beyond} |")
    return '\n'.join(lines)


def load_cores(n=2):
    """N busy processes (one per core) at normal priority."""
    return [subprocess.Popen([sys.executable, '-c', 'while True: pass']) for _ in range(n)]


def false_trips(bench, programs):
    op = bench.op
    hogs = load_cores(os.cpu_count() or 2)
    out = {'programs': programs, 'completed': 0, 'watchdog_trips': 0, 'faults': [], 'load_processes': len(hogs)}
    try:
        for _ in range(programs):
            res = op.run(SHORT, timeout=60.0)
            if res is not None and res.success:
                out['completed'] += 1
            else:
                msg = res.message if res is not None else 'no result'
                out['faults'].append(msg)
                if 'watchdog' in msg or 'heartbeat' in msg or 'no feedback' in msg or 'behind the controller' in msg:
                    out['watchdog_trips'] += 1
            bench.at_rest()
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--trials', type=int, default=20, help='trials per abort path (default 20)')
    ap.add_argument('--programs', type=int, default=30, help='programs under load for false trips (default 30)')
    ap.add_argument('--paths', default=','.join(PATHS), help='comma-separated subset of: ' + ', '.join(PATHS))
    ap.add_argument('--json', help='write the results here too')
    ap.add_argument('--stream-timeout', type=float, help=f'rig_driver stream_timeout [s] (default {STREAM_TIMEOUT})')
    ap.add_argument('--watchdog-timeout', type=float,
                    help=f'rig_driver watchdog_timeout [s] (default {WATCHDOG_TIMEOUT})')
    ap.add_argument('--heartbeat-period', type=float, help='rig_driver heartbeat_period [s] (default 0.05; must be '
                    'shorter than the watchdog timeout)')
    args = ap.parse_args(argv)
    driver_params = {name: value for name, value in (
        ('stream_timeout', args.stream_timeout), ('watchdog_timeout', args.watchdog_timeout),
        ('heartbeat_period', args.heartbeat_period)) if value is not None}
    stream_timeout = args.stream_timeout or STREAM_TIMEOUT
    watchdog_timeout = args.watchdog_timeout or WATCHDOG_TIMEOUT
    paths = [p.strip() for p in args.paths.split(',') if p.strip()]
    random.seed(11)
    domain = 100 + os.getpid() % 100
    results, errors = {}, []
    with tempfile.TemporaryDirectory(prefix='bench_safety_') as tmp:
        bench = Bench(Path(tmp), domain, driver_params)
        try:
            for path in paths:
                values, beyond_ms = [], []
                for k in range(args.trials):
                    try:
                        if path == 'stream loss':
                            values.append(bench.stream_loss())
                        elif path == 'watchdog':
                            latency, beyond = bench.watchdog(1.0 + random.uniform(0.0, 0.2), watchdog_timeout)
                            values.append(latency)
                            beyond_ms.append(beyond * 1e3)
                        else:
                            values.append(bench.operator_path(path))
                    except RuntimeError as exc:
                        errors.append(f'{path} trial {k}: {exc}')
                        bench.at_rest()
                    print(f'{path}: trial {k + 1}/{args.trials}: '
                          f'{values[-1] * 1e3 if values else float("nan"):.1f} ms', file=sys.stderr, flush=True)
                if path == 'watchdog':   # back to a rig without injected faults
                    bench.procs.stop('rig_driver')
                    bench.op.clear_history()
                    bench.procs.start('rig_driver')
                    bench.procs.wait_started('rig_driver')
                    bench.op.wait_ready(30.0)
                if values:
                    results[path] = stats(np.asarray(values) * 1e3)
                    if path == 'stream loss':
                        results[path]['detection_ms'] = int(stream_timeout * 1e3)
                    elif path == 'watchdog':
                        results[path]['detection_ms'] = int(watchdog_timeout * 1e3)
                        results[path]['beyond_ms'] = stats(beyond_ms)
            trips = false_trips(bench, args.programs) if args.programs else None
        finally:
            bench.close()
    print('## Abort latency (request -> first ramp sample, 1 kHz, each node its own process)\n')
    if driver_params:
        print(f'rig_driver: {driver_params}\n')
    print(latency_table(results))
    if trips is not None:
        print(f"\n## False watchdog trips under load ({trips['load_processes']} busy processes on "
              f"{os.cpu_count()} cores)\n")
        print('| programs | completed | watchdog trips | other faults |\n| --- | --- | --- | --- |')
        print(f"| {trips['programs']} | {trips['completed']} | {trips['watchdog_trips']} | "
              f"{len(trips['faults']) - trips['watchdog_trips']} |")
        for f in trips['faults']:
            print(f'  fault: {f}')
    for e in errors:
        print(f'error: {e}')
    if args.json:
        Path(args.json).write_text(json.dumps({'latency': results, 'false_trips': trips, 'errors': errors},
                                              indent=2))
    return 1 if errors else 0


if __name__ == '__main__':
    sys.exit(main())
