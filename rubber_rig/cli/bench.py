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

"""Run a test program on the simulated rig through the real ROS 2 nodes, with recording and a live table.

Starts rig_driver, excitation, element_model and recorder (and, with --foxglove, the Foxglove live view) in
this process, one SingleThreadedExecutor thread per node, with the same node classes and parameter file as
``ros2 launch rubber_rig rig_sim.launch.py``. The program is sent to the excitation as a RunProgram goal;
progress comes from the action feedback, the table from the element_model's cycle_metrics. At the end the
recorder is stopped and a summary (JSON and markdown) is written next to the MCAP file.

Recording is a precondition: the goal is only sent once the recorder reports RECORDING with every suite topic
subscribed (an unwritable or uncreatable output directory stops the bench before anything moves, exit 1). A
recorder that turns to ERROR during the run (disk full) stops the program (the excitation aborts; the bench
also cancels its goal) and the bench reports it. The recorder is stopped only after the rig came to rest and
the last published sample was recorded, and the summary compares the samples published with those recorded.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from rubber_rig.cli.main import CommandError
from rubber_rig.excitation.waveforms import PERIODIC, SWEEPS
from rubber_rig.paths import find_config


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--program', default='seed000_grid',
                        help='shipped program name or YAML file (default: seed000_grid, sine 0.5-14 Hz x 0.5 and '
                             '1 mm at 20 degC)')
    parser.add_argument('--config', default='rig_sim.yaml', help='ROS parameter file of the nodes '
                        '(default: the shipped config/rig_sim.yaml, as used by rig_sim.launch.py)')
    parser.add_argument('--rate', type=float, help='rig sample rate [Hz] (default: from the config, 1000)')
    parser.add_argument('--batch-size', type=int, help='samples per RigSampleBatch (default: from the config)')
    parser.add_argument('--cycles', type=int, help='full-amplitude cycles per periodic block (overrides the '
                        'program, which asks for 8)')
    parser.add_argument('--duration-scale', type=float, help='scale every block: cycles (at least 1), sweep and '
                        'hold durations (e.g. 0.25 for a quick run)')
    parser.add_argument('--blocks', help="run only these blocks, e.g. '0-3,12' (indices after grid expansion)")
    parser.add_argument('--taper-cycles', type=float, help='taper cycles in and out of periodic blocks')
    parser.add_argument('--fast', action='store_true', help='run the simulated rig as fast as possible instead of '
                        'paced to the wall clock (same waveform and physics)')
    parser.add_argument('--output-dir', default='recordings', help='directory for the MCAP file and summary')
    parser.add_argument('--namespace', default='', help='ROS namespace of the rig')
    parser.add_argument('--domain-id', type=int, help='ROS domain id (default: $ROS_DOMAIN_ID or 0)')
    parser.add_argument('--no-amplitude-control', action='store_true', help='open-loop command amplitude')
    parser.add_argument('--foxglove', action='store_true', help='serve the live topics to Foxglove over WebSocket '
                        '(layout: config/foxglove_layout.json)')
    parser.add_argument('--foxglove-port', type=int, default=8765)
    parser.add_argument('--quiet', action='store_true', help='no progress line, only the table and the result')


# -- the program ------------------------------------------------------------------------------------------------
def _block_dict(b) -> dict:
    d = {'name': b.name, 'waveform': b.waveform}
    if b.waveform in PERIODIC:
        d.update(frequency=b.frequency, amplitude=b.amplitude, mean=b.mean, cycles=int(b.cycles),
                 taper_cycles=b.taper_cycles)
        if b.waveform == 'square':
            d['rate'] = b.rate
    elif b.waveform in ('sweep_lin', 'sweep_log'):
        d.update(f_start=b.frequency, f_end=b.frequency_end, duration=b.duration, amplitude=b.amplitude,
                 mean=b.mean, taper_cycles=b.taper_cycles)
    elif b.waveform == 'hold':
        d['duration'] = b.duration
    elif b.waveform == 'ramp':
        d.update(target=b.target, duration=b.duration)
    return d


def _parse_blocks(spec: str, n: int) -> list[int]:
    out = []
    for part in spec.split(','):
        part = part.strip()
        if not part:
            continue
        lo, _, hi = part.partition('-')
        try:
            a, b = int(lo), int(hi) if hi else int(lo)
        except ValueError:
            raise ValueError(f"--blocks: {part!r} is not an index or a range like 0-3") from None
        if not (0 <= a <= b < n):
            raise ValueError(f'--blocks: {part!r} outside the program\'s blocks 0-{n - 1}')
        out.extend(range(a, b + 1))
    return out


def build_program(args) -> tuple:
    """(Program, YAML text) after the command-line overrides; validated like any program."""
    from rubber_rig.excitation import Program, load_program, read_program
    overrides = (args.cycles, args.duration_scale, args.blocks, args.taper_cycles)
    if all(v is None for v in overrides):
        return read_program(args.program)
    program = load_program(args.program)
    if args.cycles is not None and args.cycles < 1:
        raise ValueError(f'--cycles must be >= 1, got {args.cycles}')
    if args.duration_scale is not None and not args.duration_scale > 0:
        raise ValueError(f'--duration-scale must be > 0, got {args.duration_scale}')
    if args.taper_cycles is not None and not args.taper_cycles > 0:
        raise ValueError(f'--taper-cycles must be > 0, got {args.taper_cycles}')
    blocks = [_block_dict(b) for b in program.blocks]
    if args.blocks:
        blocks = [blocks[i] for i in _parse_blocks(args.blocks, len(blocks))]
    for d in blocks:
        if 'cycles' in d:
            if args.cycles is not None:
                d['cycles'] = args.cycles
            if args.duration_scale:
                d['cycles'] = max(1, int(round(d['cycles'] * args.duration_scale)))
        elif 'duration' in d and args.duration_scale and d['waveform'] != 'ramp':
            d['duration'] *= args.duration_scale
        if 'taper_cycles' in d and args.taper_cycles is not None:
            d['taper_cycles'] = args.taper_cycles
    data = {'name': program.name, 'description': program.description + ' (rubber-rig bench overrides)',
            'initial_position': program.initial_position, 'rest_position': program.rest_position, 'blocks': blocks}
    text = yaml.safe_dump(data, sort_keys=False)
    return Program.from_yaml_text(text, name=program.name), text


# -- per-block table ----------------------------------------------------------------------------------------------
class BlockTable:
    """Per-block averages of the steady cycles (full amplitude, second half of them) of cycle_metrics."""

    COLUMNS = (' blk  block                      f [Hz]  A [mm]  A meas  K_dyn meas  K_dyn model  dK [%]'
               '  C_eq meas  C_eq model  dC [%]',
               '                                                [mm]    [kN/mm]     [kN/mm]              '
               '[kN s/m]   [kN s/m]')

    def __init__(self, program):
        self.blocks = program.blocks
        self.cycles: dict[int, list] = {}
        self.printed: set[int] = set()
        self.rows: dict[int, dict] = {}

    def add(self, msg) -> list[int]:
        """Add one CycleMetrics; returns the blocks now known complete (a later block has started)."""
        if msg.block_index < 0:
            return []
        self.cycles.setdefault(msg.block_index, []).append(msg)
        return [b for b in sorted(self.cycles) if b < msg.block_index and b not in self.printed]

    @staticmethod
    def _amplitude(blk, c) -> float:
        """Measured amplitude in the program's sense: first harmonic for sines, half peak-valley otherwise."""
        return c.amplitude if blk.waveform not in ('triangle', 'square') else c.peak_amplitude

    def _row(self, b: int, name: str, frequency: float, steady: list) -> dict:
        blk = self.blocks[b]

        def mean(side, field):
            return float(np.mean([getattr(getattr(c, side), field) for c in steady])) if steady else math.nan
        r = {'block_index': b, 'name': name, 'waveform': blk.waveform, 'frequency': frequency,
             'target_amplitude': blk.amplitude,
             'achieved_amplitude': float(np.mean([self._amplitude(blk, c) for c in steady])) if steady else math.nan,
             'cycles_used': len(steady)}
        for side in ('measured', 'model'):
            r[side] = {n: mean(side, n) for n in ('k_dyn', 'loss_angle', 'damping', 'c_eq', 'energy_harmonic',
                                                  'energy_loop')}
        r['deviation_k_dyn_pct'] = 100 * (r['model']['k_dyn'] / r['measured']['k_dyn'] - 1)
        r['deviation_c_eq_pct'] = 100 * (r['model']['c_eq'] / r['measured']['c_eq'] - 1)
        return r

    def row_list(self, b: int) -> list[dict]:
        """Rows of block b: one for a periodic block, one per frequency band of a sweep, none otherwise."""
        blk = self.blocks[b]
        cycles = self.cycles.get(b, [])
        if blk.waveform in PERIODIC:
            cyc = [c for c in cycles if self._amplitude(blk, c) >= 0.9 * blk.amplitude
                   and abs(c.frequency - blk.frequency) <= 0.1 * blk.frequency]
            rows = [self._row(b, blk.name, blk.frequency, cyc[len(cyc) // 2:] if len(cyc) > 1 else cyc)]
        elif blk.waveform in SWEEPS:
            # a sweep has no steady state: group its cycles into bands around 1-1.5-2-3-5-7 x 10^n Hz (+-10 %),
            # past the tapers (half the target amplitude; the actuator attenuates the top of a sweep)
            lo, hi = sorted((blk.frequency, blk.frequency_end))
            bands = [m * 10.0 ** e for e in range(-2, 4) for m in (1, 1.5, 2, 3, 5, 7) if lo <= m * 10.0 ** e <= hi]
            rows = []
            for fc in bands:
                cyc = [c for c in cycles if c.amplitude >= 0.5 * blk.amplitude and abs(c.frequency / fc - 1) <= 0.1]
                if cyc:
                    rows.append(self._row(b, f'{blk.name} @{fc:g}Hz', float(np.mean([c.frequency for c in cyc])),
                                          cyc))
        else:
            rows = []
        self.rows[b] = rows
        return rows

    def format(self, b: int) -> list[str]:
        self.printed.add(b)
        return [(f"{b:4d}  {r['name'][:24]:<24}  {r['frequency']:6.2f}  {r['target_amplitude'] * 1e3:6.3f}  "
                 f"{r['achieved_amplitude'] * 1e3:6.3f}  {r['measured']['k_dyn'] * 1e-6:10.3f}  "
                 f"{r['model']['k_dyn'] * 1e-6:11.3f}  {r['deviation_k_dyn_pct']:+6.2f}  "
                 f"{r['measured']['c_eq'] * 1e-3:9.2f}  {r['model']['c_eq'] * 1e-3:10.2f}  "
                 f"{r['deviation_c_eq_pct']:+6.2f}") for r in self.row_list(b)]


class Terminal:
    """Table rows scroll; the progress line is rewritten in place on a terminal (printed every few s otherwise)."""

    def __init__(self, quiet: bool):
        self.tty = sys.stdout.isatty() and not quiet
        self.quiet = quiet
        self._last_plain = 0.0
        self._status = ''

    def line(self, text: str) -> None:
        if self.tty and self._status:
            sys.stdout.write('\r' + ' ' * min(len(self._status), shutil.get_terminal_size().columns - 1) + '\r')
        print(text, flush=True)
        if self.tty and self._status:
            sys.stdout.write(self._status)
            sys.stdout.flush()

    def status(self, text: str) -> None:
        if self.quiet:
            return
        width = shutil.get_terminal_size().columns - 1
        if self.tty:
            self._status = text[:width]
            sys.stdout.write('\r' + self._status.ljust(width)[:width] + '\r' + self._status)
            sys.stdout.flush()
        elif time.monotonic() - self._last_plain >= 5.0:
            self._last_plain = time.monotonic()
            print(text, flush=True)

    def end_status(self) -> None:
        if self.tty and self._status:
            sys.stdout.write('\n')
            self._status = ''


def progress_text(fb, stats, t_start) -> str:
    achieved = '--' if math.isnan(fb.achieved_amplitude) else f'{fb.achieved_amplitude * 1e3:.3f}'
    return (f'[{fb.progress * 100:5.1f}%] block {fb.block_index + 1}/{fb.block_count} {fb.block_name}  '
            f'cycle {fb.cycle}/{fb.cycles_total}  A {fb.target_amplitude * 1e3:.3f} mm -> {achieved} mm  '
            f'| {stats.samples} samples, {stats.gaps} gaps | {time.monotonic() - t_start:5.1f} s')


# -- summary --------------------------------------------------------------------------------------------------------
def write_summary(mcap: Path, summary: dict) -> tuple[Path, Path]:
    base = mcap.with_suffix('')
    jpath, mpath = Path(f'{base}.summary.json'), Path(f'{base}.summary.md')
    jpath.write_text(json.dumps(summary, indent=2, default=float) + '\n')
    lines = [f"# rubber-rig bench: {summary['program']}", '',
             f"- recording: `{summary['recording']}`",
             f"- rig: {summary['rig']['backend']}, {summary['rig']['sample_rate']:g} Hz, "
             f"{'paced' if summary['rig']['paced'] else 'fast'}; specimen {summary['rig']['specimen']}",
             f"- model: {summary['model']['parameter_set'] or summary['model']['source']} "
             f"({', '.join(f'{k}={v:.4g}' for k, v in summary['model']['values'].items())})",
             f"- result: {summary['result']['message']} in {summary['wall_time_s']:.1f} s wall time",
             f"- samples: {summary['loss']['live']['samples']['samples']} published, "
             f"{summary['loss']['live']['samples']['gaps']} gaps; predictions "
             f"{summary['loss']['live']['prediction']['samples']}, "
             f"{summary['loss']['live']['prediction']['gaps']} gaps;"
             f" recording: {summary['loss']['recording'].get('samples_lost', 'n/a')} samples lost",
             ]
    lat = summary.get('latency', {}).get('last_sample')
    if lat:
        lines.append(f"- latency sample -> prediction: median {lat['median_ms']:.2f} ms, p99 {lat['p99_ms']:.2f} ms")
    lines += ['', '| block | name | f [Hz] | A [mm] | A meas [mm] | K_dyn meas [kN/mm] | K_dyn model [kN/mm] | '
              'dK [%] | C_eq meas [kN s/m] | C_eq model [kN s/m] | dC [%] | loss angle meas/model [deg] |',
              '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for r in summary['blocks']:
        lines.append(f"| {r['block_index']} | {r['name']} | {r['frequency']:.2f} | {r['target_amplitude'] * 1e3:.3f} | "
                     f"{r['achieved_amplitude'] * 1e3:.3f} | {r['measured']['k_dyn'] * 1e-6:.3f} | "
                     f"{r['model']['k_dyn'] * 1e-6:.3f} | {r['deviation_k_dyn_pct']:+.2f} | "
                     f"{r['measured']['c_eq'] * 1e-3:.2f} | {r['model']['c_eq'] * 1e-3:.2f} | "
                     f"{r['deviation_c_eq_pct']:+.2f} | {math.degrees(r['measured']['loss_angle']):.2f} / "
                     f"{math.degrees(r['model']['loss_angle']):.2f} |")
    mpath.write_text('\n'.join(lines) + '\n')
    return jpath, mpath


def _wait(launcher, future, timeout: float, what: str):
    if not launcher.wait_for(future.done, timeout):
        raise CommandError(f'timed out after {timeout:.0f} s waiting for {what}')
    return future.result()


# -- the job -----------------------------------------------------------------------------------------------------------
def refuse_if_another_suite_runs(launcher, namespace: str, discovery_time: float = 1.5) -> None:
    """Two suites with the same topics on one ROS domain would command one rig from two excitations (and
    record each other): wait for DDS discovery, and refuse to start if a rig_driver or excitation node
    already runs in this namespace.
    """
    from rclpy.node import Node
    probe = launcher.spin(Node('rubber_rig_bench_probe', context=launcher.context, namespace=namespace or None))
    ns = '/' + namespace.strip('/') if namespace.strip('/') else '/'

    def others():
        return sorted(f"{n_ns.rstrip('/')}/{name}" for name, n_ns in probe.get_node_names_and_namespaces()
                      if name in ('rig_driver', 'excitation') and n_ns == ns)
    if launcher.wait_for(lambda: bool(others()), discovery_time):
        domain = launcher.context.get_domain_id()
        raise CommandError(f"another rubber_rig suite runs on ROS domain {domain} in namespace '{ns}' "
                           f"({', '.join(others())}): give this one its own --domain-id or --namespace")


def run(args) -> int:
    os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    from msg_defs.msg import RigStatus
    from msg_defs.srv import RecorderControl
    from rubber_rig.nodes.element_model import ElementModelNode
    from rubber_rig.nodes.excitation import ExcitationNode
    from rubber_rig.nodes.launcher import InProcessLauncher
    from rubber_rig.nodes.monitor import SuiteMonitor
    from rubber_rig.nodes.recorder import RecorderNode
    from rubber_rig.nodes.rig_driver import RigDriverNode

    config = find_config(args.config)
    program, program_yaml = build_program(args)
    out_dir = Path(args.output_dir).absolute()     # created by the recorder, which reports if it cannot
    driver_overrides = {'autostart': True}
    if args.rate:
        driver_overrides['sample_rate'] = float(args.rate)
    if args.batch_size:
        driver_overrides['batch_size'] = int(args.batch_size)
    if args.fast:
        driver_overrides['paced'] = False
    term = Terminal(args.quiet)

    with InProcessLauncher([config], namespace=args.namespace, domain_id=args.domain_id) as launcher:
        refuse_if_another_suite_runs(launcher, args.namespace)
        recorder = launcher.start(RecorderNode, {
            'output_dir': str(out_dir), 'metadata.test_program': program_yaml,
            'metadata.notes': f'rubber-rig bench --program {args.program}'})
        if not recorder.core.recording:              # before any other node exists: nothing can move
            raise CommandError(f'cannot record, nothing started: {recorder.core.error or "recorder not recording"}')
        model = launcher.start(ElementModelNode)
        excitation = launcher.start(ExcitationNode, {'program': ''})
        driver = launcher.start(RigDriverNode, driver_overrides)
        if driver.lifecycle_state != 'active':
            raise CommandError(f'rig_driver did not come up (lifecycle state {driver.lifecycle_state}); see the log')
        if args.foxglove:
            from rubber_rig.nodes.foxglove_view import LAYOUT_FILE, FoxgloveViewNode
            launcher.start(FoxgloveViewNode, {'port': args.foxglove_port})
        monitor = launcher.spin(SuiteMonitor(context=launcher.context, namespace=args.namespace))

        cfg = driver.config
        rate = cfg.sample_rate
        specimen = cfg.sim.specimen
        p = model.predictor
        term.line(f"rubber-rig bench: program '{program.name}' ({len(program.blocks)} blocks, "
                  f'{program.duration(rate):.1f} s of excitation at {rate:g} Hz, '
                  f"{'paced' if cfg.paced else 'as fast as possible'})")
        term.line(f"rig: {cfg.backend}, specimen {specimen}; model seed000 from "
                  f"{p.parameter_set or p.choice.source}")
        term.line('nodes: rig_driver, excitation, element_model, recorder'
                  + (', foxglove_view' if args.foxglove else '') + ' (one SingleThreadedExecutor thread each)')
        if args.foxglove:
            term.line(f'Foxglove: connect to ws://127.0.0.1:{args.foxglove_port}, import layout {LAYOUT_FILE}')

        # the excitation must have seen the rig ready (not the driver's first, pre-configure status), and the
        # recorder must record every stream (matched with its publisher) before the first setpoint is sent
        recorded_topics = ('samples', 'prediction', 'setpoints', 'cycle_metrics', 'status')

        def recorder_failed():
            st = monitor.recorder_status
            return st is not None and st.state == st.STATE_ERROR

        ready = launcher.wait_for(lambda: recorder_failed() or (
            monitor.status is not None and monitor.action.server_is_ready() and excitation.rig_ready() == ''
            and monitor.recording_ready(*recorded_topics) == ''), 30.0)
        if recorder_failed():
            raise CommandError(f'cannot record, nothing moved: {monitor.recording_ready()}')
        if not ready:
            why = excitation.rig_ready() or monitor.recording_ready(*recorded_topics) or 'run_program missing'
            raise CommandError(f'the nodes did not connect within 30 s ({why})')
        term.line(f'recording to {monitor.recorder_status.path}')
        table = BlockTable(program)
        term.line(BlockTable.COLUMNS[0])
        term.line(BlockTable.COLUMNS[1])

        t_start = time.monotonic()
        goal_handle = _wait(launcher, monitor.send_program(program_yaml, amplitude_control=not
                                                           args.no_amplitude_control), 30.0, 'the goal to be accepted')
        if not goal_handle.accepted:
            raise CommandError('the excitation refused the program: another program is running on this ROS domain '
                               '(a second bench? give it its own --domain-id)')
        result_future = goal_handle.get_result_async()
        n_fb = n_cm = 0
        interrupted = False
        recording_error = ''
        try:
            while not result_future.done():
                launcher.check()
                if recorder_failed() and not recording_error:
                    # the excitation aborts on its own (require_recording); cancelling is the bench's safe ramp
                    recording_error = monitor.recorder_status.error
                    term.end_status()
                    term.line(f'RECORDING FAILED: {recording_error}; stopping the program (smooth ramp to rest)')
                    goal_handle.cancel_goal_async()
                fb = monitor.feedback[n_fb:]
                n_fb += len(fb)
                if fb:
                    term.status(progress_text(fb[-1], monitor.stats['samples'], t_start))
                cms = monitor.cycle_metrics[n_cm:]
                n_cm += len(cms)
                for c in cms:
                    for b in table.add(c):
                        for line in table.format(b):
                            term.line(line)
                # the screen refreshes ten times a second, at once when the program ends
                launcher.wait_for(result_future.done, 0.1)
        except KeyboardInterrupt:
            interrupted = True
            term.end_status()
            term.line('interrupted: aborting the program (smooth ramp to rest) ...')
            goal_handle.cancel_goal_async()
            launcher.wait_for(result_future.done, 15.0)
        term.end_status()
        wall = time.monotonic() - t_start
        launcher.wait_for(lambda: False, 0.5)   # let the last cycle metrics arrive
        for c in monitor.cycle_metrics[n_cm:]:
            table.add(c)
        for b in sorted(table.cycles):
            if b not in table.printed:
                for line in table.format(b):
                    term.line(line)
        result = result_future.result().result if result_future.done() else None

        # stop the recorder only once the rig has been at rest for a while (a fault's ramp tail arrives after the
        # goal ended) and every sample published so far has been recorded. A paced rig goes on sampling while it
        # stands: the run's samples are those published up to that moment (the snapshot), not those that keep
        # arriving until the recorder stops.
        samples_topic = monitor.resolve_topic_name('samples')
        moving = (RigStatus.STATE_RUNNING, RigStatus.STATE_RAMPING_DOWN)
        rest = {'since': None, 'published': None}

        def tail_recorded():
            mon = monitor.stats['samples']
            st = monitor.status
            # unpaced (--fast), the simulated controller only ticks while setpoints are queued: after the
            # program it still says running, holding its last setpoint, but the driver has released the stream
            at_rest = st is not None and (st.state not in moving
                                          or (st.state == RigStatus.STATE_RUNNING and not st.stream_owner))
            if not at_rest:
                rest['since'] = None
                return False
            if rest['since'] is None:
                rest['since'] = time.monotonic()
            settled = time.monotonic() - rest['since'] >= 2 * driver.max_batch_delay
            recorded = recorder_failed() or mon.next is None \
                or recorder.core.gaps.next_expected.get(samples_topic, -1) >= mon.next
            if settled and recorded:
                rest['published'] = copy.copy(mon)
            return settled and recorded
        if not launcher.wait_for(tail_recorded, 10.0):
            term.line('warning: the rig did not come to rest or the recorder did not receive the last samples '
                      'within 10 s; the summary counts what is missing')
        if recorder_failed() and not recording_error:
            recording_error = monitor.recorder_status.error

        stop = _wait(launcher, monitor.recorder(RecorderControl.Request.STOP), 30.0, 'the recorder to stop')
        if not stop.file:
            raise CommandError(f'the recorder did not report its file: {stop.message or "no message"}')
        mcap = Path(stop.file)
        published = rest['published'] or monitor.stats['samples']
        rec_loss = recording_loss(mcap, published, recorder.core.stats())
        if recording_error:
            rec_loss['recorder_error'] = recording_error
        summary = {
            'program': program.name, 'recording': str(mcap), 'wall_time_s': wall, 'interrupted': interrupted,
            'rig': {'backend': cfg.backend, 'sample_rate': rate, 'paced': cfg.paced, 'specimen': specimen,
                    'batch_size': driver.batch_size},
            'model': {'source': p.choice.source, 'parameter_set': p.parameter_set, 'temperature': p.temperature,
                      'values': p.params.as_dict()},
            'result': {'success': bool(result.success) if result else False,
                       'message': result.message if result else 'no result (interrupted)',
                       'blocks': [{'block_index': b.block_index, 'name': b.name, 'target_amplitude': b.target_amplitude,
                                   'achieved_amplitude': b.achieved_amplitude, 'completed': b.completed,
                                   'message': b.message} for b in (result.blocks if result else [])]},
            'loss': {'live': {k: v.as_dict() for k, v in monitor.stats.items()}, 'recording': rec_loss},
            # stamps are rig time (sample index / rate): only a paced rig keeps it in step with the wall clock
            'latency': monitor.latency_summary() if cfg.paced else {},
            'blocks': [r for b in sorted(table.rows) for r in table.rows[b]],
        }
        try:
            jpath, mpath = write_summary(mcap, summary)
            summary_error = ''
        except OSError as exc:   # e.g. the disk that stopped the recording is full: print it instead
            jpath = mpath = None
            summary_error = f'cannot write the summary next to {mcap}: {exc.strerror or exc}'
            print(json.dumps(summary, indent=2, default=float))

    live = summary['loss']['live']
    print(f"\nprogram: {summary['result']['message']} ({wall:.1f} s)")
    print(f"samples: {live['samples']['samples']} published, {live['samples']['gaps']} gaps; "
          f"predictions: {live['prediction']['samples']}, {live['prediction']['gaps']} gaps; "
          f"recording: {rec_loss.get('samples_lost', 'n/a')} samples lost"
          + (f" ({rec_loss['samples_not_recorded']} published samples not recorded)"
             if rec_loss.get('samples_not_recorded') else ''))
    if recording_error:
        print(f'RECORDING FAILED: {recording_error}')
    lat = summary['latency'].get('last_sample')
    if lat:
        print(f"latency sample -> prediction: median {lat['median_ms']:.2f} ms, p99 {lat['p99_ms']:.2f} ms")
    elif not cfg.paced:
        print('latency: not measured with --fast (rig time runs ahead of the wall clock)')
    print(f'MCAP recording: {mcap}' + ('' if rec_loss.get('complete', True) else
                                       ' (not closed: readable up to its last complete chunk)'))
    if summary_error:
        print(f'summary:        NOT WRITTEN ({summary_error}); printed above as JSON')
    else:
        print(f'summary:        {jpath}')
        print(f'                {mpath}')
    if interrupted:
        return 130
    return 0 if summary['result']['success'] and not recording_error else 1


def recording_loss(mcap: Path, published, recorder_stats: dict) -> dict:
    """Loss of the recording: what the file itself shows (sequence gaps that are real loss) plus every sample
    published during the run (``published``: the monitor's StreamStats of ``samples``) that is not in the file.
    ``samples_lost`` is the total; it is never 0 while a published sample is missing.
    """
    from rubber_rig.recording import load_recording
    try:
        rec = load_recording(mcap, allow_truncated=True)
    except Exception as exc:   # the summary still says where the file is and what is known missing
        return {'error': str(exc), 'samples_lost': published.samples or 'unknown',
                'samples_not_recorded': published.samples}
    seq = np.asarray(rec.sequence, dtype=np.int64)
    if published.first is not None:
        in_run = int(np.count_nonzero((seq >= published.first) & (seq < published.next)))
    else:
        in_run = 0
    not_recorded = max(0, published.samples - in_run)
    return {'samples': int(len(rec)), 'samples_lost': int(rec.samples_lost) + not_recorded,
            'samples_lost_in_file': int(rec.samples_lost), 'samples_not_recorded': not_recorded,
            'samples_published': published.samples, 'gaps': len(rec.gaps), 'sequence_jumps': len(rec.jumps),
            'complete': bool(rec.complete), 'unclosed': rec.unclosed,
            'recorder_samples_lost': recorder_stats.get('samples_lost_total'),
            'topics': {t: v.get('count') for t, v in rec.topics.items()}}
