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
import os
import time
from pathlib import Path

from rubber_rig.cli.bench_view import Terminal, print_result, progress_text
from rubber_rig.cli.main import CommandError
from rubber_rig.excitation import load_program, read_program
from rubber_rig.excitation.program import OverrideError, with_overrides
from rubber_rig.online.summary import BlockTable, write_summary
from rubber_rig.paths import find_config
from rubber_rig.recording.loss import recording_loss


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
def build_program(args) -> tuple:
    """(Program, YAML text) after the command-line overrides; validated like any program."""
    overrides = {'cycles': args.cycles, 'duration_scale': args.duration_scale, 'blocks': args.blocks,
                 'taper_cycles': args.taper_cycles}
    if all(v is None for v in overrides.values()):
        return read_program(args.program)
    program = load_program(args.program)
    try:
        return with_overrides(program, **overrides, note='rubber-rig bench overrides')
    except OverrideError as exc:
        raise ValueError(f"--{exc.field.replace('_', '-')}: {exc.why}") from None


# -- summary --------------------------------------------------------------------------------------------------------
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
    from rubber_rig.nodes.element_model_node import ElementModelNode
    from rubber_rig.nodes.excitation_node import ExcitationNode
    from rubber_rig.nodes.launcher import InProcessLauncher
    from rubber_rig.nodes.monitor import SuiteMonitor
    from rubber_rig.nodes.recorder_node import RecorderNode
    from rubber_rig.nodes.rig_driver_node import RigDriverNode

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
            from rubber_rig.nodes.foxglove_view_node import LAYOUT_FILE, FoxgloveViewNode
            launcher.start(FoxgloveViewNode, {'port': args.foxglove_port})
        monitor = launcher.spin(SuiteMonitor(context=launcher.context, namespace=args.namespace))

        cfg = driver.config
        rate = cfg.sample_rate
        specimen = cfg.sim.specimen
        p = model.predictor
        term.line(f"rubber-rig bench: program '{program.name}' ({len(program.blocks)} blocks, "
                  f'{program.duration(rate):.1f} s of excitation at {rate:g} Hz, '
                  f"{'paced' if cfg.paced else 'as fast as possible'})")
        term.line(f"rig: {cfg.backend}, specimen {specimen}; model fractional_zener_berg from "
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
        # the last cycle metrics are out once the model has predicted every published sample
        launcher.wait_for(lambda: monitor.stats['prediction'].next is not None and monitor.stats['samples'].next
                          is not None and monitor.stats['prediction'].next >= monitor.stats['samples'].next, 5.0)
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

    print_result(summary, rec_loss, recording_error, cfg.paced, mcap, jpath, mpath, summary_error)
    if interrupted:
        return 130
    return 0 if summary['result']['success'] and not recording_error else 1
