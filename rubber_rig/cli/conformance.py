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

"""Check a rig controller against the rig protocol specification (docs/protocol.md).

Online, against a controller on a python-can bus, with small motion inside the envelope you state:
  rubber-rig conformance --interface socketcan --channel can0 --envelope 1mm --markdown report.md --junit report.xml
  rubber-rig conformance --sim --envelope 1mm              # the simulated controller, in a process of its own
  rubber-rig conformance --sim --defect heartbeat_80ms     # ... with a deliberate defect (see docs/protocol.md)
  rubber-rig conformance --reference --reference-defect force_in_kN   # the second controller, written from the spec
Measured values (CTRL-MEAS-1..3) need the reference spring on the rig and the ambient declared:
  rubber-rig conformance --interface socketcan --channel can0 --envelope 1mm --reference-spring 10kN/mm±1% \
      --ambient 23degC±5K
Offline, from a raw CAN log recorded on a rig (what a log can show: periods, counters, CRCs, feedback rate,
timing, continuity, sequence width, the host's duties):
  rubber-rig conformance --log run.blf --rate 1000Hz
Exit status: 0 every requirement checked passed, 1 a requirement failed, 2 usage error or refusal, 3 the run
left the envelope and was aborted, 4 (online) nothing failed but the run is incomplete: a requirement was not
tested (e.g. CTRL-PWR-1 without --power-up). Offline, requirements a log does not show are listed, not failed.
"""
import ctypes
import datetime
import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time

import can

from rubber_rig import __version__
from rubber_rig.rig.can.bus import open_bus
from rubber_rig.rig.can.canlog import CanLogError, check_log_path
from rubber_rig.rig.can.protocol import DBC_PATH, PROTOCOL_VERSION
from rubber_rig.rig.config import ConfigError, RigConfig
from rubber_rig.rig.conformance.active import ConformanceRun
from rubber_rig.rig.conformance.defects import DEFECTS
from rubber_rig.rig.conformance.host_timing import LATE_MIN, SIM_LATE_MIN
from rubber_rig.rig.conformance.in_process import REFERENCE_AMBIENT, REFERENCE_SPRING, run_against_reference
from rubber_rig.rig.conformance.kernel_counts import OWN_WAITS, RUN_QUEUE_MIN, cpu_pressure, pressure_share
from rubber_rig.rig.conformance.link import SCENARIO_THREAD, Aborted, Envelope
from rubber_rig.rig.conformance.log_segments import check_log
from rubber_rig.rig.conformance.reference_specimen import Ambient, ReferenceSpring
from rubber_rig.rig.conformance.report import NOT_TESTED, to_junit, to_markdown
from rubber_rig.rig.conformance.requirements import REQUIREMENTS
from rubber_rig.rig.conformance.trace import read_log
from rubber_rig.rig.reference import REFERENCE_DEFECTS
from rubber_rig.settings import describe_violation, described
from rubber_rig.units import to_si

from .main import CommandError

EXIT_FAIL, EXIT_ABORTED, EXIT_INCOMPLETE = 1, 3, 4


def add_arguments(parser):
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument('--interface', help='python-can interface of the bus the controller is on (socketcan, pcan, '
                     'vector, kvaser, udp_multicast, ...)')
    src.add_argument('--sim', action='store_true', help='test the simulated controller, started as a process of '
                     'its own on a udp_multicast bus that stays on this host')
    src.add_argument('--reference', action='store_true', help='test the reference controller (a second controller '
                     'written from the specification alone, rubber_rig.rig.reference) in this process on a virtual '
                     'bus, on simulated time (deterministic; --wall-clock: in real time, in a thread); with '
                     '--reference-defect it breaks a duty on purpose')
    src.add_argument('--log', help='offline: check a raw CAN log (.blf, .asc, candump .log) recorded on a rig')
    parser.add_argument('--channel', help='python-can channel (e.g. can0)')
    parser.add_argument('--bitrate', type=int, default=1_000_000, help='CAN bit rate [bit/s] (default %(default)d)')
    parser.add_argument('--data-bitrate', type=int, default=5_000_000, help='CAN FD data bit rate [bit/s]')
    parser.add_argument('--classic', action='store_true', help='classic CAN (no FD): the classic frame profile')
    parser.add_argument('--profile', choices=('packed', 'single', 'classic'), help='frame profile (default: packed '
                        'on CAN FD, classic on classic CAN)')
    parser.add_argument('--bus-options', default='{}', help='extra can.Bus keyword arguments as JSON')
    parser.add_argument('--rate', default='1000Hz', help='the controller\'s sample rate (default %(default)s)')
    parser.add_argument('--envelope', help='online: the displacement the run may use, +- this (e.g. 1mm); '
                        'required: nothing moves without it')
    parser.add_argument('--envelope-lower', help='lower end of the envelope where it is not symmetric (e.g. -0.5mm)')
    parser.add_argument('--power-up', action='store_true', help='online: also check power-up (CTRL-PWR-1): the run '
                        'listens first, then asks you to switch the controller on (--sim: starts it)')
    parser.add_argument('--yes', action='store_true', help='the operator confirms the envelope without a prompt')
    parser.add_argument('--defect', action='append', default=[], choices=sorted(DEFECTS),
                        help='with --sim: a deliberate protocol defect of the simulated controller (repeatable)')
    parser.add_argument('--wall-clock', action='store_true', help='with --reference: run the reference controller in '
                        'real time in a thread of this process, not on simulated time')
    parser.add_argument('--reference-defect', action='append', default=[], choices=sorted(REFERENCE_DEFECTS),
                        help='with --reference: a deliberate defect of the reference controller (repeatable)')
    parser.add_argument('--reference-spring', help='online: the reference spring on the rig and its expanded '
                        'uncertainty (k = 2), e.g. 10kN/mm±1%% (or +-1%%): the run judges stiffness, force sign, '
                        'unit, scale and delay against it (CTRL-MEAS-1/2); --sim and --reference put it on their rig')
    parser.add_argument('--ambient', help='online: the specimen temperature and the tolerance of a reading, e.g. '
                        '23degC±5K (default tolerance 5 K): judges the temperature (CTRL-MEAS-3)')
    parser.add_argument('--markdown', help='write the report as Markdown to this file')
    parser.add_argument('--junit', help='write the report as JUnit XML to this file')
    parser.add_argument('--can-log', help='online: also write every frame of the run to this raw CAN log')


def _split(text: str) -> tuple[str, str | None]:
    parts = re.split(r'\s*(?:±|\+-|\+/-)\s*', text.strip())
    if len(parts) > 2:
        raise ValueError(f'{text!r}: one value and at most one +- tolerance')
    return parts[0], (parts[1] if len(parts) == 2 else None)


def parse_reference_spring(text: str) -> ReferenceSpring:
    """'10kN/mm±1%' (or '+-1%', or an absolute '+-0.1kN/mm') -> ReferenceSpring; ValueError naming what is
    wrong. Without a tolerance: 1 %.
    """
    value, tol = _split(text)
    k = to_si(value, 'stiffness')
    if tol is None:
        u = 0.01
    elif tol.endswith('%'):
        u = float(tol[:-1]) / 100.0
    else:
        u = to_si(tol, 'stiffness') / k
    return ReferenceSpring(k, u)


def parse_ambient(text: str) -> Ambient:
    """'23degC±2K' -> Ambient (tolerance in K; default 5 K); ValueError naming what is wrong."""
    value, tol = _split(text)
    t = to_si(value, 'temperature')
    if tol is None:
        return Ambient(t)
    tol_k = float(tol[:-1]) if tol.endswith('K') else to_si(tol, 'temperature') - to_si('0degC', 'temperature')
    return Ambient(t, tol_k)


def check_arguments(args):
    """Combinations argparse cannot check; a message here is a usage error (exit 2)."""
    try:
        args.rate_hz = to_si(args.rate, 'frequency')
        args.upper = to_si(args.envelope, 'length') if args.envelope else None
        args.lower = to_si(args.envelope_lower, 'length') if args.envelope_lower else None
    except ValueError as exc:
        return f'{exc}'
    rate = described(RigConfig, 'sample_rate')
    why = describe_violation(rate.range, None, rate.units, args.rate_hz)
    if why:
        return f'argument --rate: {why}'
    try:
        args.reference_spring_declared = (parse_reference_spring(args.reference_spring) if args.reference_spring
                                          else None)
        args.ambient_declared = parse_ambient(args.ambient) if args.ambient else None
    except ValueError as exc:
        return f'argument --reference-spring/--ambient: {exc}'
    if args.wall_clock and not args.reference:
        return '--wall-clock is for the reference controller (--reference); other runs are in real time'
    if args.reference_defect and not args.reference:
        return '--reference-defect is for the reference controller (--reference)'
    if args.log:
        if args.envelope or args.defect or args.can_log or args.reference_spring or args.ambient:
            return ('--log checks a recording: --envelope, --defect, --can-log, --reference-spring and --ambient are '
                    'for an online run')
        return None
    if args.reference and args.upper is None:
        args.upper = 1e-3           # the reference controller's rig is virtual: +-1 mm unless stated
    if args.upper is None:
        return ('an online run moves the actuator: state the displacement envelope it may use with --envelope '
                '(e.g. --envelope 1mm), inside what the specimen and fixture allow')
    if args.lower is None:
        args.lower = -args.upper
    if args.defect and not args.sim:
        return '--defect is for the simulated controller (--sim)'
    try:
        Envelope(args.lower, args.upper)
    except ValueError as exc:
        return f'argument --envelope: {exc}'
    if args.can_log:
        try:
            check_log_path(args.can_log)
        except CanLogError as exc:
            return f'argument --can-log: {exc}'
    return None


def _provenance() -> list:
    """When, with what tool and which protocol definition a report was made (a test record names them)."""
    digest = hashlib.sha256(DBC_PATH.read_bytes()).hexdigest()[:16]
    now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')
    return [f'{now}, rubber_rig {__version__}, {DBC_PATH.name} protocol version {PROTOCOL_VERSION} (sha256 '
            f'{digest}...)']


def _write(args, results, title, facts, elapsed):
    md = to_markdown(results, title, _provenance() + list(facts))
    print(md)
    if args.markdown:
        with open(args.markdown, 'w', encoding='utf-8') as f:
            f.write(md)
    if args.junit:
        with open(args.junit, 'w', encoding='utf-8') as f:
            f.write(to_junit(results, title, elapsed))


def _offline(args) -> int:
    t0 = time.monotonic()
    try:
        trace = read_log(args.log, args.rate_hz)
    except (CanLogError, OSError) as exc:
        raise CommandError(str(exc)) from None
    results = check_log(trace).complete({r.id for r in REQUIREMENTS if r.offline}, 'not shown by this log')
    facts = [f'log {args.log}: {len(trace.frames)} frames over {trace.end - trace.start:.3f} s, judged at '
             f'{args.rate_hz:g} Hz', f'rig protocol version {PROTOCOL_VERSION}; offline: only what a log can show']
    facts.append(trace.log_verdict())   # the log's own faults, apart from the controller's verdicts
    facts += [f'warning: {w}' for w in trace.warnings]
    _write(args, results, 'rubber_rig protocol conformance (offline)', facts, time.monotonic() - t0)
    return EXIT_FAIL if not results.passed else 0


def _config(args) -> RigConfig:
    data = {'backend': args.interface or 'udp_multicast', 'channel': args.channel, 'bitrate': args.bitrate,
            'data_bitrate': args.data_bitrate, 'fd': not args.classic, 'profile': args.profile or '',
            'sample_rate': args.rate_hz, 'bus_options': json.loads(args.bus_options)}
    if args.sim:
        port = 43000 + os.getpid() % 5000     # a port of its own: another run on this host stays apart
        data['channel'] = data['channel'] or '239.74.163.7'
        data['bus_options'] = {'port': port, **data['bus_options']}
        data['sim'] = {'defects': list(args.defect)}
        if args.reference_spring_declared:     # the declared reference spring is the simulated specimen
            data['sim']['specimen'] = {'model': 'linear', 'stiffness': args.reference_spring_declared.stiffness,
                                       'damping': 0.0}
        if args.ambient_declared:
            data['sim']['temperature'] = args.ambient_declared.temperature
    return RigConfig.from_dict(data)


def _confirm(args) -> bool:
    if args.yes:
        return True
    print(f'The controller will move the actuator inside {args.lower * 1e3:g} .. {args.upper * 1e3:g} mm at a few '
          'mm/s, with steps of up to 1.5 x its rated velocity for one sample. Is the specimen and fixture safe '
          'there? Type yes to start: ', end='', flush=True)
    return sys.stdin.readline().strip().lower() == 'yes'


def run(args) -> int:
    if args.log:
        return _offline(args)
    if args.reference:
        return _reference(args)
    try:
        cfg = _config(args)
    except (ConfigError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    if not args.sim and not _confirm(args):
        print('rubber-rig conformance: not confirmed: nothing was sent', file=sys.stderr)
        return 2
    box = {}
    # the simulator runs on this host: its missed deadlines are this host's lateness, not the controller's
    timing_dir = tempfile.TemporaryDirectory(prefix='rubber_rig_conformance_') if args.sim else None
    timing_files = [os.path.join(timing_dir.name, 'sim_late.txt')] if timing_dir else []
    sim_command = [sys.executable, '-m', 'rubber_rig.rig.sim', '--config-json', json.dumps(cfg.to_dict()),
                   *(['--timing-log', timing_files[0]] if timing_files else [])]

    watch = []        # the simulator's process: its waits for a CPU are this host's lateness (kernel_counts)

    def start_sim():
        box['process'] = subprocess.Popen(sim_command, stdout=subprocess.DEVNULL, preexec_fn=_ends_with_this_process())
        watch.append(box['process'].pid)

    def ask_operator():
        print('rubber-rig conformance: switch the controller on now (waiting 60 s)', file=sys.stderr, flush=True)
    power_up = (start_sim if args.sim else ask_operator) if args.power_up else None
    if args.sim and not args.power_up:
        start_sim()
    try:
        bus = open_bus(cfg)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        if 'process' in box:
            box['process'].terminate()
        raise CommandError(f'cannot open the bus {cfg.backend} {cfg.channel or ""}: {exc}') from None
    t0 = time.monotonic()
    try:
        conf = ConformanceRun(bus, cfg.sample_rate, Envelope(args.lower, args.upper), cfg.frame_profile,
                              log=lambda text: print(text, file=sys.stderr, flush=True), power_up=power_up,
                              host_timing_files=timing_files, reference=args.reference_spring_declared,
                              ambient=args.ambient_declared)
        conf.link.kernel.pids = watch
        pressure = cpu_pressure()
        results = conf.run()
        pressure = pressure_share(pressure, cpu_pressure(), time.monotonic() - t0)
        if args.can_log:
            conf.trace_to_log(args.can_log)
    except Aborted as exc:
        print(f'rubber-rig conformance: aborted: {exc}', file=sys.stderr)
        return EXIT_ABORTED
    finally:
        bus.shutdown()
        if 'process' in box:
            box['process'].terminate()
            box['process'].wait(timeout=10)
        if timing_dir is not None:
            timing_dir.cleanup()
    simulated = f" (simulated, defects: {', '.join(args.defect) or 'none'})" if args.sim else ''
    return _online_report(args, conf, results, f'bus {cfg.backend} {cfg.channel or ""}, {cfg.frame_profile} '
                          f'frames, {cfg.sample_rate:g} Hz', simulated, t0, pressure)


def _ends_with_this_process():
    """A preexec_fn: the kernel sends SIGTERM to the child when this process ends, however (PR_SET_PDEATHSIG): a
    run killed by a timeout leaves no simulator loading the host for ever. None without prctl.
    """
    prctl = getattr(ctypes.CDLL(None, use_errno=True), 'prctl', None)    # looked up before the fork
    return None if prctl is None else (lambda: prctl(1, signal.SIGTERM, 0, 0, 0))   # 1: PR_SET_PDEATHSIG


def _reference(args) -> int:
    """The reference controller in this process on a virtual bus (power-up included)."""
    t0 = time.monotonic()
    profile = args.profile or ('classic' if args.classic else 'packed')
    reference = args.reference_spring_declared or REFERENCE_SPRING
    ambient = args.ambient_declared or REFERENCE_AMBIENT
    args.power_up = True
    try:
        conf, results = run_against_reference(args.reference_defect, args.rate_hz, Envelope(args.lower, args.upper),
                                              profile, reference, ambient,
                                              log=lambda text: print(text, file=sys.stderr, flush=True),
                                              wall_clock=args.wall_clock)
        if args.can_log:
            conf.trace_to_log(args.can_log)
    except Aborted as exc:
        print(f'rubber-rig conformance: aborted: {exc}', file=sys.stderr)
        return EXIT_ABORTED
    what = (f" (the reference controller, rubber_rig.rig.reference, on a {reference.describe()} spring at "
            f"{ambient.temperature:g} degC; defects: {', '.join(args.reference_defect) or 'none'})")
    clock = 'in real time' if args.wall_clock else 'on simulated time'
    return _online_report(args, conf, results, f'virtual bus in this process {clock}, {profile} frames, '
                          f'{args.rate_hz:g} Hz', what, t0)


def _host_timing_fact(args, timing, pressure) -> str:
    """What this host's own lateness was during the run, by source, and the CPU pressure (share of the run some
    task of this host waited for a CPU; None: not measured).
    """
    late = [b - a for a, b in timing.windows]
    thresholds = {'receive loop and heartbeat': LATE_MIN, SCENARIO_THREAD: LATE_MIN, 'simulator': SIM_LATE_MIN,
                  'reference controller': SIM_LATE_MIN, 'run-queue waits of the simulator': RUN_QUEUE_MIN,
                  OWN_WAITS: RUN_QUEUE_MIN}
    parts = [f'{name} {count} (' + (f'by {thresholds[name] * 1e3:g} ms or more, ' if name in thresholds else '')
             + f'{seconds:.3f} s)' for name, (count, seconds) in sorted(timing.sources.items())]
    who = ('the simulator' if args.sim else 'the reference controller' if args.reference else 'none')
    text = (f'host timing: this host ran late {len(late)} times' + (f": {', '.join(parts)}" if parts else '')
            + (f'; longest {max(late) * 1e3:.0f} ms' if late else '') + f' (process standing for the controller '
            f'on this host: {who}); a timing requirement violated only by as much as this host was late, or a '
            "scenario's FAIL where this host was late as long as the requirement's time tolerance, is not judged")
    if pressure is not None:
        text += (f'; CPU pressure: some task of this host waited for a CPU {pressure * 100:.0f} % of the run '
                 '(/proc/pressure/cpu, context only)')
    return text


def _online_report(args, conf, results, bus: str, controller: str, t0: float, pressure=None) -> int:
    """Facts, report and exit status of an online run."""
    ident = conf.identity[1] if conf.identity else None
    facts = [bus, f'envelope {args.lower * 1e3:g} .. {args.upper * 1e3:g} mm (stated by the operator)',
             'controller: ' + (f"device 0x{int(ident['CI_Device']):04x}, firmware {int(ident['CI_Firmware'])}, "
                               f"protocol {int(ident['CI_Protocol'])}" if ident else 'did not identify itself')
             + controller,
             'measured values judged against: ' + ', '.join(
                 ([f'the reference spring {conf.reference.describe()}'] if conf.reference else
                  ['no reference spring declared']) +
                 ([f'the ambient {conf.ambient.temperature:g} degC +- {conf.ambient.tolerance:g} K']
                  if conf.ambient else ['no ambient declared'])),
             'host requirements (HOST-*) are checked offline on a log written by the driver']
    facts.append(_host_timing_fact(args, conf.host_timing, pressure))
    if conf.deviation:
        facts.append(f'ABORTED: {conf.deviation}')
    untested = [r.id for r in results.ordered() if r.status == NOT_TESTED]
    if untested and results.passed and not conf.deviation:
        facts.append(f'INCOMPLETE: {len(untested)} requirements not tested ({", ".join(untested)}): this run does '
                     'not show the controller conforms')
    _write(args, results, 'rubber_rig protocol conformance', facts, time.monotonic() - t0)
    return online_exit_status(results, bool(conf.deviation))


def online_exit_status(results, aborted: bool) -> int:
    """The exit status of an online run: aborted 3, a requirement failed 1, one not tested 4 (incomplete), 0."""
    if aborted:
        return EXIT_ABORTED
    if not results.passed:
        return EXIT_FAIL
    return EXIT_INCOMPLETE if results.count(NOT_TESTED) else 0
