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

"""Rates, loss and latency of the whole node suite on the simulated rig, paced to the wall clock.

    .venv/bin/python benchmarks/bench_suite.py --rate 1000 --duration 600          # the 10-minute 1 kHz run
    .venv/bin/python benchmarks/bench_suite.py --rate 1000,2000,3000 --duration 60  # highest zero-loss rate
    .venv/bin/python benchmarks/bench_suite.py --processes ...                      # one process per node
    .venv/bin/python benchmarks/bench_suite.py --rate 10000 --duration 60           # packed CAN FD at 10 kHz
    .venv/bin/python benchmarks/bench_suite.py --rate 1000 --classic --profile classic   # a classic CAN bus

rig_driver (simulated rig on the simulated CAN bus with bit timing: CAN FD 1/5 Mbit/s with packed frames unless
--bitrate, --data-bitrate, --classic, --profile say otherwise; the bus load measured on it is reported),
excitation (a 5 Hz, 1 mm sine, open loop),
element_model and recorder run as threads of one process (one SingleThreadedExecutor thread per node) or, with
--processes, as separate processes the way ros2 launch and `rubber-rig bench` start them
(rubber_rig.cli.processes); --spawn-sim puts the simulated rig in a process of its own too (udp_multicast over
loopback, no bit timing), so that the nodes' CPU is measured without it. A monitor node subscribes like any client.
--nodes-from runs the node processes of another checkout (an older commit) under the same monitor and accounting:
old and new back to back in one run.

Loss is counted three ways: sequence gaps seen live by the monitor (samples, predictions, setpoints); gaps and
lost samples in the MCAP recording read back from disk; and "starved" samples, where the command the rig
applied differs from the program's setpoint (the driver ran out of setpoints). Latency: from a sample being
taken to the prediction for it arriving at the monitor, for the first sample of each batch (the bus timestamp of
its frame: includes waiting for the batch to fill) and for the last one (estimated as first + (n-1)/rate: the
pipeline delay alone; when the simulated rig catches up late ticks in a burst, this estimate runs early).

CPU, with its conditions (rubber_rig.cpu): per process over the program (utime + stime from /proc as % of one core;
the executor thread's wake-ups per second and CPU per wake-up), the CPU all other programs used meanwhile and the
1-minute load average at start and end; a run during which others used more than 0.1 core says MEASURED UNDER LOAD.
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rubber_rig.cpu import CpuMeter, child_pids

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'rig_sim.yaml'
FREQUENCY, AMPLITUDE = 5.0, 1e-3


def program_text(duration: float) -> str:
    cycles = max(1, int(round(duration * FREQUENCY)) - 2)
    return (f'name: bench_suite\nblocks:\n  - {{name: sine, waveform: sine, frequency: {FREQUENCY}, '
            f'amplitude: {AMPLITUDE}, cycles: {cycles}, taper_cycles: 1}}\n')


def driver_extra(args, domain: int) -> dict:
    from rubber_rig.cli.processes import separate_sim_rig
    extra = separate_sim_rig(domain) if args.spawn_sim else {}
    if args.poll_period:
        extra['poll_period'] = args.poll_period
    for key, value in (('can.profile', args.profile), ('can.bitrate', args.bitrate),
                       ('can.data_bitrate', args.data_bitrate)):
        if value:
            extra[key] = value
    if args.classic:
        extra['can.fd'] = False
    return extra


def bus_name(args) -> str:
    if args.spawn_sim:
        return 'udp_multicast (no bit timing)'
    bitrate = (args.bitrate or 1_000_000) / 1e6
    if args.classic:
        return f'classic {bitrate:g} Mbit/s'
    return f'CAN FD {bitrate:g}/{(args.data_bitrate or 5_000_000) / 1e6:g} Mbit/s'


def start_processes(args, rate, batch, out_dir, domain):
    """Each node in its own process, as ros2 launch starts them (rubber_rig.cli.processes.SuiteProcesses); with
    --nodes-from, the nodes of another checkout (its code on PYTHONPATH, its config/rig_sim.yaml).
    """
    from rubber_rig.cli.processes import SuiteProcesses
    config = Path(args.nodes_from) / 'config' / 'rig_sim.yaml' if args.nodes_from else CONFIG
    overrides = {'recorder': {'output_dir': str(out_dir), 'discovery_period': 0.2},
                 'excitation': {'batch_size': batch},
                 'rig_driver': dict({'sample_rate': float(rate), 'batch_size': args.batch_size or 0},
                                    **driver_extra(args, domain))}
    procs = SuiteProcesses(config, '/', domain, out_dir / f'logs_{rate:g}Hz', overrides)
    if args.nodes_from:
        procs.env['PYTHONPATH'] = str(Path(args.nodes_from).resolve())
        procs.cwd = str(Path(args.nodes_from).resolve())   # python -m puts the working directory first on sys.path
    procs.start_all(('recorder', 'element_model', 'excitation', 'rig_driver'))
    return procs


def watched_processes(procs) -> dict:
    """{name: pid} of the processes whose CPU the run reports: each node process (or this one, holding them all),
    the simulated rig's process when it has one (a child of rig_driver's), and this benchmark's own (the monitor).
    """
    me = os.getpid()
    if procs is None:
        watched = {'suite+monitor': me}
        sims = child_pids(me)
    else:
        watched = dict(procs.pids(), monitor=me)
        sims = child_pids(watched['rig_driver']) if 'rig_driver' in watched else []
    watched.update({f'sim_rig{i or ""}': pid for i, pid in enumerate(sims)})
    return watched


def run_once(args, rate: float, out_dir: Path) -> dict:
    from msg_defs.srv import RecorderControl
    from rubber_rig.excitation import Program
    from rubber_rig.launching.inprocess import InProcessLauncher
    from rubber_rig.nodes.excitation_readiness import READY_STATES
    from rubber_rig.nodes.monitor import SuiteMonitor
    from rubber_rig.nodes.rig_driver_node import BATCH_PERIOD
    from rubber_rig.recording import load_recording

    # setpoints: ~20 messages/s; samples: rig_driver's own default (10 ms of samples) unless --batch-size
    batch = args.batch_size or max(20, int(round(rate / 20)))
    sample_batch = args.batch_size or max(1, round(BATCH_PERIOD * rate))
    domain = args.domain_id if args.domain_id is not None else 150 + os.getpid() % 50
    text = program_text(args.duration)
    program = Program.from_yaml_text(text)
    procs, driver = None, None
    launcher = InProcessLauncher([CONFIG], domain_id=domain)
    try:
        if args.processes:
            procs = start_processes(args, rate, batch, out_dir, domain)
        else:
            from rubber_rig.nodes.element_model_node import ElementModelNode
            from rubber_rig.nodes.excitation_node import ExcitationNode
            from rubber_rig.nodes.recorder_node import RecorderNode
            from rubber_rig.nodes.rig_driver_node import RigDriverNode
            launcher.start(RecorderNode, {'output_dir': str(out_dir), 'discovery_period': 0.2})
            launcher.start(ElementModelNode)
            launcher.start(ExcitationNode, {'batch_size': batch})
            driver_params = dict({'sample_rate': float(rate), 'batch_size': args.batch_size or 0},
                                 **driver_extra(args, domain))
            driver = launcher.start(RigDriverNode, driver_params)
        mon = launcher.spin(SuiteMonitor(context=launcher.context))
        # the rig ready, not just any status (the driver's first one, before autostart, says 'unconfigured')
        if not launcher.wait_for(lambda: mon.status is not None and mon.status.state in READY_STATES
                                 and mon.action.server_is_ready() and
                                 mon.recorder_subscribed('samples', 'prediction', 'setpoints'), 60.0):
            raise RuntimeError('suite did not come up within 60 s')
        # The graph lists the recorder's subscriptions as soon as they exist; across processes, DDS endpoint
        # matching can take a moment longer, and messages published before it completes never reach them.
        launcher.wait_for(lambda: False, 2.0 if args.processes else 0.2)
        medium = driver.rig.medium if driver is not None and driver.rig is not None else None
        busy0 = medium.stats['busy_time'] if medium is not None else None
        meter = CpuMeter(watched_processes(procs)).start()
        t0 = time.monotonic()
        goal = mon.send_program(text, amplitude_control=False)
        if not launcher.wait_for(goal.done, 30.0) or not goal.result().accepted:
            raise RuntimeError('program not accepted')
        result = goal.result().get_result_async()
        launcher.wait_for(result.done, args.duration * 3 + 60.0)
        wall = time.monotonic() - t0
        # the bus's busy fraction over the run, measured on the simulated bus with bit timing
        bus_load = (medium.stats['busy_time'] - busy0) / wall if medium is not None else None
        tx_dropped = (driver.rig.sim.counters.get('tx_dropped', 0) if driver is not None and driver.rig
                      and driver.rig.sim else None)
        launcher.wait_for(lambda: False, 1.0)   # last batches
        cpu = meter.stop()
        stop = mon.recorder(RecorderControl.Request.STOP)
        launcher.wait_for(stop.done, 60.0)
        mcap = Path(stop.result().file)
        live = {k: v.as_dict() for k, v in mon.stats.items()}
        latency = mon.latency_summary()
        sim = dict(driver.rig.sim.counters) if driver is not None and driver.rig and driver.rig.sim else {}
        status = mon.status
        message = result.result().result.message if result.done() else 'did not finish'
        # 'completed' (older nodes) or 'completed (recording complete in <file>)'
        success = result.done() and bool(result.result().result.success) and message.startswith('completed')
    finally:
        launcher.shutdown()
        if procs is not None:
            procs.stop_all()     # SIGINT, as ros2 launch stops its nodes
    rec = load_recording(mcap)
    expected = program.setpoints(rate)
    inside = rec.sequence < len(expected)
    bad = np.abs(rec.setpoint[inside] - expected[rec.sequence[inside]]) > 1e-7
    starved = int(np.sum(bad))
    seq_bad = rec.sequence[inside][bad]
    breaks = np.flatnonzero(np.diff(seq_bad) != 1) + 1 if seq_bad.size else np.array([], int)
    starved_runs = [(int(r[0]), int(r.size)) for r in np.split(seq_bad, breaks)][:10] if seq_bad.size else []
    missing_in_program = len(expected) - int(inside.sum())
    reasons = [name for name, bad in (
        ('recording: samples lost', rec.samples_lost > 0), ('recording: sequence gaps', bool(rec.gaps)),
        ('starved samples', starved > 0), ('program samples not recorded', missing_in_program > 0),
        ('live gaps', any(v['gaps'] for v in live.values())), ('bus frames lost', status.frames_lost > 0),
        ('program samples without prediction', bool(np.any(~np.isfinite(rec.prediction[inside])))),
        ('program did not complete', not success)) if bad]
    pred_gaps = [g for g in rec.gaps if 'prediction' in str(g.get('topic', ''))] if rec.gaps else []
    return {
        'rate': rate, 'batch_size': sample_batch,
        'mode': ('processes' if args.processes else 'one process') + (', sim rig apart' if args.spawn_sim else ''),
        'duration_s': wall, 'program': message,
        'samples_expected': len(expected), 'samples_recorded': int(len(rec)),
        'recording_samples_lost': int(rec.samples_lost), 'recording_gaps': len(rec.gaps),
        'recording_prediction_gaps': len(pred_gaps), 'program_samples_missing': missing_in_program,
        'starved_samples': starved, 'starved_runs': starved_runs,
        'predictions_recorded': int(np.sum(np.isfinite(rec.prediction))),
        'program_samples_without_prediction': int(np.sum(~np.isfinite(rec.prediction[inside]))),
        'first_sequences_without_prediction': rec.sequence[inside][~np.isfinite(rec.prediction[inside])][:5].tolist(),
        'live': live, 'frames_lost': int(status.frames_lost), 'frames_late': int(status.frames_late),
        'latency': latency, 'cpu_cores': cpu.watched_cores, 'cpu': cpu.as_dict(), 'cpu_lines': cpu.lines(),
        'nodes_from': args.nodes_from or str(ROOT), 'bus_load': bus_load, 'tx_dropped': tx_dropped,
        'profile': args.profile or ('classic' if args.classic else 'packed'), 'sim_counters': sim,
        'recording': str(mcap),
        'loss_reasons': reasons,
        'zero_loss': not reasons,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rate', default='1000', help='rig rate(s) [Hz], comma separated (default 1000)')
    parser.add_argument('--duration', type=float, default=60.0, help='seconds of excitation per rate (600 = the '
                        '10-minute run)')
    parser.add_argument('--batch-size', type=int, help='samples per batch (default: rig_driver 10 ms of samples, '
                        'excitation rate/20, at least 20)')
    parser.add_argument('--poll-period', type=float, help='rig_driver poll_period [s] (default: its parameter)')
    parser.add_argument('--profile', choices=('packed', 'single', 'classic'), help='CAN frame profile (default: '
                        'packed on CAN FD, classic with --classic)')
    parser.add_argument('--bitrate', type=int, help='CAN (arbitration) bitrate [bit/s] (default 1 Mbit/s)')
    parser.add_argument('--data-bitrate', type=int, help='CAN FD data bitrate [bit/s] (default 5 Mbit/s)')
    parser.add_argument('--classic', action='store_true', help='a classic CAN bus (no FD)')
    parser.add_argument('--processes', action='store_true', help='one process per node instead of one thread each')
    parser.add_argument('--spawn-sim', action='store_true', help="simulated rig in a process of its own, on "
                        "python-can's udp_multicast bus over loopback (instead of a thread on the virtual bus)")
    parser.add_argument('--nodes-from', help='with --processes: run the nodes of this checkout (its code on '
                        'PYTHONPATH, its config/rig_sim.yaml), e.g. an older commit for a back-to-back comparison '
                        '(git worktree add /tmp/old COMMIT); the monitor and the loss accounting stay this one')
    parser.add_argument('--output-dir', help='keep the recordings here (default: a temporary directory)')
    parser.add_argument('--domain-id', type=int, help='ROS domain (default: a private one)')
    parser.add_argument('--json', help='also write the results to this JSON file')
    args = parser.parse_args(argv)
    if args.nodes_from and not args.processes:
        parser.error('--nodes-from needs --processes')
    os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    rates = [float(r) for r in args.rate.split(',')]
    results = []
    with tempfile.TemporaryDirectory(prefix='bench_suite_') as tmp:
        out = Path(args.output_dir or tmp)
        out.mkdir(parents=True, exist_ok=True)
        for rate in rates:
            print(f'--- {rate:g} Hz, {args.duration:g} s, {"processes" if args.processes else "one process"} ...',
                  flush=True)
            r = run_once(args, rate, out)
            results.append(r)
            lat = r['latency'].get('last_sample', {})
            lat1 = r['latency'].get('first_sample', {})
            print(f"    {r['program']}; {r['samples_recorded']} samples recorded of {r['samples_expected']} "
                  f"in the program; lost: recording {r['recording_samples_lost']} ({r['recording_gaps']} gaps), "
                  f"live gaps samples/prediction/setpoints {r['live']['samples']['gaps']}/"
                  f"{r['live']['prediction']['gaps']}/{r['live']['setpoints']['gaps']}, "
                  f"starved {r['starved_samples']}, "
                  f"bus frames lost {r['frames_lost']}"
                  + (f" (starved runs [first sequence, length]: {r['starved_runs']})" if r['starved_runs'] else ''),
                  flush=True)
            print("    latency sample->prediction: last sample of batch median "
                  f"{lat.get('median_ms', float('nan')):.1f}"
                  f" ms, p99 {lat.get('p99_ms', float('nan')):.1f} ms; first sample median "
                  f"{lat1.get('median_ms', float('nan')):.1f} ms, p99 {lat1.get('p99_ms', float('nan')):.1f} ms; "
                  f"CPU {r['cpu_cores']:.2f} cores (below); "
                  + (f"bus load {r['bus_load'] * 100:.1f} % (controller frames dropped {r['tx_dropped']}); "
                     if r['bus_load'] is not None else '') +
                  f"{'ZERO LOSS' if r['zero_loss'] else 'LOSS: ' + ', '.join(r['loss_reasons'])}", flush=True)
            print('    CPU over the run (utime+stime / wall time; wake-ups: the executor thread blocking):', flush=True)
            for line in r['cpu_lines']:
                print('  ' + line, flush=True)
    print('\n| rate [Hz] | bus, frames | batch | mode | duration [s] | samples | lost (rec) | gaps (live) | starved | '
          'bus load (measured) | latency first sample median / p99 [ms] | last sample median / p99 [ms] | '
          'CPU [cores] | others on the machine [cores] | zero loss |')
    print('|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|')
    for r in results:
        lat = r['latency'].get('last_sample', {})
        lat1 = r['latency'].get('first_sample', {})
        gaps = sum(v['gaps'] for v in r['live'].values())
        load = f"{r['bus_load'] * 100:.1f} %" if r['bus_load'] is not None else 'n/a'
        print(f"| {r['rate']:g} | {bus_name(args)}, {r['profile']} | {r['batch_size']} | {r['mode']} | "
              f"{r['duration_s']:.0f} | {r['samples_recorded']} | "
              f"{r['recording_samples_lost']} | {gaps} | {r['starved_samples']} | {load} | "
              f"{lat1.get('median_ms', float('nan')):.1f} / {lat1.get('p99_ms', float('nan')):.1f} | "
              f"{lat.get('median_ms', float('nan')):.1f} / {lat.get('p99_ms', float('nan')):.1f} | "
              f"{r['cpu_cores']:.2f} | {r['cpu']['other_cores_used']:.2f}"
              f"{' (UNDER LOAD)' if r['cpu']['under_load'] else ''} | {'yes' if r['zero_loss'] else 'NO'} |")
    ok = [r['rate'] for r in results if r['zero_loss']]
    print(f"\nhighest zero-loss rate in this run: {max(ok):g} Hz" if ok else '\nno rate ran without loss')
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2, default=float))
    return 0 if len(ok) == len(results) else 1


if __name__ == '__main__':
    sys.exit(main())
