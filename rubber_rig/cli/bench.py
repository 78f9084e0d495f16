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

Starts rig_driver, excitation, element_model and recorder (and, with --foxglove, the Foxglove live view) each in a
process of its own, as ``ros2 launch rubber_rig rig_sim.launch.py`` does (same executables, same parameter file),
with the paced simulated rig in a process of its own on a bus that crosses processes (cli.bench_nodes); with
--in-process, as threads of this process (one SingleThreadedExecutor each). This process holds a monitor node.
The program is sent to the excitation as a RunProgram goal; progress comes from the action feedback, the table
from the element_model's cycle_metrics. At the end the recorder is stopped and a summary (JSON and markdown) is
written next to the MCAP file.

Recording is a precondition: the goal is only sent once the recorder reports RECORDING with every suite topic
subscribed (an unwritable or uncreatable output directory stops the bench before anything moves, exit 1). A
recorder that turns to ERROR during the run (disk full) stops the program (the excitation aborts; the bench
also cancels its goal) and the bench reports it. The recorder is stopped only after the rig came to rest and
the last published sample was recorded, and the summary compares the samples published with those recorded.

The closing lines give the latency from a sample being taken to its prediction arriving here (first and last
sample of a batch, median and p99) and the CPU each process used while the program ran, with the machine's load
meanwhile (rubber_rig.cpu): a run on a busy machine says so.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
from contextlib import contextmanager
from pathlib import Path

from rubber_rig.cli.bench_view import Terminal, print_result
from rubber_rig.cli.main import CommandError
from rubber_rig.cpu import CpuMeter, child_pids
from rubber_rig.excitation import load_program, read_program
from rubber_rig.excitation.program import OverrideError, with_overrides
from rubber_rig.online.summary import BlockTable, write_summary
from rubber_rig.paths import find_config
from rubber_rig.security import KEY_ENV, default_key_path, init_key, load_key


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--program', default='dynamic_stiffness_grid',
                        help='shipped program name or YAML file (default: dynamic_stiffness_grid, sine 0.5-14 Hz '
                             'x 0.5 and 1 mm at 20 degC)')
    parser.add_argument('--key-file', help='the rig\'s secret key (default: $RUBBER_RIG_KEY_FILE, else '
                        '~/.config/rubber_rig/rig.key, created if missing: rubber-rig keys init)')
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
    parser.add_argument('--force-noise', help="simulated load-cell noise, e.g. '200N' (default: from the config)")
    parser.add_argument('--damage', help="how the simulated specimen fails (YAML list), e.g. "
                        "\"[{type: crack, cycle: 200, loss: 0.3}]\"; types fatigue, crack, slip (README 'Detectors')")
    parser.add_argument('--hold-timeout', help="how long a held program waits for a resume before it ends, "
                        "e.g. '30s' (default: the excitation config, 600 s)")
    parser.add_argument('--output-dir', default='recordings', help='directory for the MCAP file and summary')
    parser.add_argument('--namespace', default='', help='ROS namespace of the rig')
    parser.add_argument('--domain-id', type=int, help='ROS domain id (default: $ROS_DOMAIN_ID or 0)')
    parser.add_argument('--no-amplitude-control', action='store_true', help='open-loop command amplitude')
    parser.add_argument('--foxglove', action='store_true', help='serve the live topics to Foxglove over WebSocket '
                        '(layout: config/foxglove_layout.json)')
    parser.add_argument('--foxglove-port', type=int, default=8765)
    parser.add_argument('--quiet', action='store_true', help='no progress line, only the table and the result')
    parser.add_argument('--in-process', action='store_true', help='run the nodes as threads of this process (one '
                        'executor thread each, the simulated rig a thread of rig_driver) instead of one process '
                        'each as ros2 launch starts them')


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


# -- the job -----------------------------------------------------------------------------------------------------------
def refuse_if_another_suite_runs(launcher, namespace: str, discovery_time: float = 1.5) -> None:
    """Two suites with the same topics on one ROS domain would command one rig from two excitations (and
    record each other): refuse to start if a rig_driver or excitation node already runs in this namespace.
    Returns as soon as one is discovered; otherwise after ``discovery_time`` [s], the one wait that must run
    its course (that no other suite runs only shows as DDS discovery not finding one).
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


def show_rows(term, table: BlockTable, blocks) -> None:
    """Print the table rows of the given (complete) blocks."""
    for b in blocks:
        for line in table.format(b):
            term.line(line)


def save_summary(mcap: Path, summary: dict) -> tuple:
    """(JSON path, Markdown path, '') of the summary written next to the recording; where it cannot be written
    (e.g. the disk that stopped the recording is full) it is printed as JSON instead: (None, None, why).
    """
    try:
        return (*write_summary(mcap, summary), '')
    except OSError as exc:
        print(json.dumps(summary, indent=2, default=float))
        return None, None, f'cannot write the summary next to {mcap}: {exc.strerror or exc}'


def ensure_key(key_file: str | None) -> str:
    """Make the rig's key known to the nodes and clients the bench starts (RUBBER_RIG_KEY_FILE) and create it when
    there is none yet, so that the shipped configuration works out of the box. Returns a line to show, or ''.
    """
    if key_file:
        os.environ[KEY_ENV] = str(Path(key_file).expanduser().absolute())
    path = default_key_path()
    if path.exists():
        load_key(path)      # a key others can read is refused here, before any node starts (KeyFileError names it)
        return ''
    init_key(path)
    return f'created the rig key {path} (mode 0600; rubber-rig keys init)'


def run(args) -> int:
    os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    from rubber_rig.cli.bench_nodes import InProcessNodes, NodeProcesses, domain_of
    from rubber_rig.cli.bench_session import BenchSession  # rclpy is loaded only when the bench runs
    from rubber_rig.launching.inprocess import InProcessLauncher

    config = find_config(args.config)
    program, program_yaml = build_program(args)
    key_note = ensure_key(args.key_file)          # before any node starts: each reads the key at start
    out_dir = Path(args.output_dir).absolute()     # created by the recorder, which reports if it cannot
    term = Terminal(args.quiet)
    table = BlockTable(program)
    domain = domain_of(args.domain_id)

    def on_cycle(c):                               # a block is complete (printed) once a later one has started
        show_rows(term, table, table.add(c))

    with InProcessLauncher([config], namespace=args.namespace, domain_id=domain) as launcher, \
            stopped_on_terminate():
        refuse_if_another_suite_runs(launcher, args.namespace)
        nodes = InProcessNodes(launcher) if args.in_process else NodeProcesses(config, args.namespace, domain)
        try:
            session = BenchSession(launcher, nodes, args, program_yaml, out_dir, config)
            recording = session.wait_ready()
            for line in ([key_note] if key_note else []) + list(session.describe(program)):
                term.line(line)
            term.line(f'recording to {recording}')
            term.line(BlockTable.COLUMNS[0])
            term.line(BlockTable.COLUMNS[1])
            meter = CpuMeter(watched_processes(nodes)).start()
            outcome = session.run_program(program_yaml, not args.no_amplitude_control, on_cycle, term)
            cpu = meter.stop()
            session.catch_up(outcome, table.add, term)
            show_rows(term, table, [b for b in sorted(table.cycles) if b not in table.printed])
            mcap, rec_loss = session.stop_recording(outcome, term)
            summary = session.summary(program, mcap, outcome, rec_loss,
                                      [r for b in sorted(table.rows) for r in table.rows[b]])
            summary['cpu'] = dict(cpu.as_dict(), nodes=nodes.description)
            jpath, mpath, summary_error = save_summary(mcap, summary)
        finally:
            nodes.close()

    print_result(summary, rec_loss, outcome.recording_error, session.cfg.paced, mcap, jpath, mpath, summary_error)
    print_cpu(cpu, args.in_process)
    if outcome.interrupted:
        return 130
    return 0 if summary['result']['success'] and not outcome.recording_error else 1


def watched_processes(nodes) -> dict:
    """{name: pid} whose CPU the bench reports: each node process, the simulated rig's (a child of rig_driver's)
    and this one (the monitor and the table; with --in-process, every node as well).
    """
    watched = dict(nodes.pids())
    watched['bench' if watched else 'bench+nodes'] = os.getpid()
    sims = child_pids(watched['rig_driver']) if 'rig_driver' in watched else [
        pid for pid in child_pids(os.getpid()) if pid not in watched.values()]
    watched.update({f'sim_rig{i or ""}': pid for i, pid in enumerate(sims)})
    return watched


def print_cpu(cpu, in_process: bool) -> None:
    """The CPU each process used while the program ran, and what else the machine did meanwhile."""
    print(f'CPU while the program ran ({cpu.wall_time:.0f} s; % of one core'
          + (', every node in this one process' if in_process else '') + '):')
    for line in cpu.lines():
        print(line)


@contextmanager
def stopped_on_terminate():
    """SIGTERM or SIGHUP (a closed terminal) end the bench like Ctrl-C: the program ramps to rest, the recording
    is closed and the node processes are stopped, instead of leaving them running on their own.
    """
    def interrupt(signum, frame):
        raise KeyboardInterrupt
    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
