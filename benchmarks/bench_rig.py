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

"""Rig benchmark: driver + simulated rig (seed-000 specimen) without ROS, for each frame profile of the CAN
protocol (rubber_rig.rig.can.frames: packed CAN FD, single-sample CAN FD, classic 8-byte CAN).

1. What each bus profile carries (the protocol's load from the DBC, worst-case bit stuffing).
2. Cost per sample of the frame path: fast (as fast as possible) runs of a sine program through driver and
   simulated controller, every frame encoded, sent over python-can's virtual bus, decoded. Side by side in one
   run: the single-sample frames (protocol 2's only profile) and the packed frames. The marginal cost per
   sample (a long minus a short run: rig start-up and shutdown excluded) and the whole-run cost are reported.
3. With --paced: real-time runs on the simulated bus with bit timing (rubber_rig.rig.can.simbus), reporting the
   bus load measured on it, frames lost and the controller's transmit-queue drops.

    .venv/bin/python benchmarks/bench_rig.py                  # tables 1 and 2 (60 s programs)
    .venv/bin/python benchmarks/bench_rig.py --paced 10000    # also 10 kHz in real time on the timed bus
    .venv/bin/python benchmarks/bench_rig.py --duration 10    # shorter

Exit status 1 if any run lost a frame or did not complete.
"""
import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
import argparse
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from rubber_rig.excitation import Program  # noqa: E402
from rubber_rig.rig import open_rig  # noqa: E402
from rubber_rig.rig.can.timing import protocol_load  # noqa: E402
from rubber_rig.session import run_program  # noqa: E402


def program(duration: float) -> Program:
    """A sine program of `duration` s: 5 Hz, 0.5 mm, 1 taper cycle in and out."""
    cycles = int(round(duration * 5)) - 2
    return Program.from_yaml_text(f'name: bench_{duration:g}s\nblocks:\n  - {{waveform: sine, frequency: 5 Hz, '
                                  f'amplitude: 0.5 mm, cycles: {cycles}, taper_cycles: 1}}\n')


def run(rate: float, duration: float, paced: bool, profile: str, fd: bool = True, bitrate: int = 1_000_000,
        data_bitrate: int = 5_000_000) -> dict:
    prog = program(duration)
    # the paced simulator shares this process (and its GIL) with the host loop on a loaded machine: a wall-clock
    # heartbeat watchdog of 1 s keeps a starved thread from aborting the run (hardware has its own CPU)
    cfg = {'paced': paced, 'sample_rate': rate, 'watchdog_timeout': 1.0 if paced else 0.25, 'profile': profile,
           'fd': fd, 'bitrate': bitrate, 'data_bitrate': data_bitrate, 'max_bus_load': 1.0}
    c0, t0 = time.process_time(), time.perf_counter()
    with open_rig(cfg) as rig:
        busy0, w0 = (rig.medium.stats['busy_time'], time.perf_counter()) if rig.medium else (None, None)
        r = run_program(prog, cfg, rig=rig)
        # busy fraction of the bus over the run, measured on the simulated bus with bit timing (paced)
        load = (rig.medium.stats['busy_time'] - busy0) / (time.perf_counter() - w0) if rig.medium else None
        sim = dict(rig.sim.counters)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    n = int(r.sequence.size)
    st = r.final_status
    return dict(rate=rate, profile=profile, mode='paced' if paced else 'fast', samples=n,
                expected=prog.n_samples(rate), lost=st.frames_lost, late=st.frames_late, malformed=st.frames_malformed,
                completed=r.completed, wall=wall, cpu=cpu, achieved=n / wall, wall_us=wall / n * 1e6,
                cpu_us=cpu / n * 1e6, realtime=(n / rate) / wall, message=r.message, load=load,
                expected_load=st.extra['bus_load'], tx_dropped=sim.get('tx_dropped', 0))


PROFILES = (('classic 500 kbit/s', 500_000, None, False, 'classic'),
            ('classic 1 Mbit/s', 1_000_000, None, False, 'classic'),
            ('FD 1/5 single', 1_000_000, 5_000_000, True, 'single'),
            ('FD 1/5 packed', 1_000_000, 5_000_000, True, 'packed'),
            ('FD 1/8 packed', 1_000_000, 8_000_000, True, 'packed'))
# cost runs: (profile, rate, fd, bitrate) side by side
COST_RUNS = (('single', 1000.0), ('single', 2000.0), ('classic', 1000.0), ('packed', 1000.0), ('packed', 2000.0),
             ('packed', 5000.0), ('packed', 10000.0))
TODAY_US = 93.0   # protocol 2 (single-sample frames), the issue's figure on this machine


def bus_profiles(rates) -> None:
    """What the protocol (the DBC) needs of each bus profile: load at each rate (worst-case bit stuffing) and the
    highest rate at 50 %, 70 % and 100 % load.
    """
    print('bus load of the protocol (rubber_rig.rig.can.timing, worst-case bit stuffing):')
    print(f"{'profile':>20} " + ' '.join(f'{r:>8.0f}' for r in rates) + f" {'@50 %':>8} {'@70 %':>8} {'full':>8}")
    for name, bitrate, data_bitrate, fd, profile in PROFILES:
        try:
            loads = [protocol_load(r, bitrate, data_bitrate, fd=fd, profile=profile) for r in rates]
        except ValueError as exc:
            print(f'{name:>20}  cannot carry it: {str(exc).split(": ", 1)[1]}')
            continue
        top = loads[0]
        print(f'{name:>20} ' + ' '.join(f'{ld.load * 100:7.0f}%' for ld in loads)
              + f' {top.rate_at(0.5):8.0f} {top.rate_at(0.7):8.0f} {top.max_rate:8.0f}')
    print()


def cost_table(duration: float) -> bool:
    """Cost per sample of driver + simulated controller for each profile, side by side in this run."""
    print(f'cost per sample, driver + simulated controller, fast runs of a {duration:g} s sine program on the virtual '
          f'bus, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}')
    print(f"{'profile':>8} {'rate':>6} {'samples':>8} {'lost':>5} {'wall s':>7} {'x real time':>11} "
          f"{'us/sample':>9} {'marginal us/sample':>18} {'cpu us/sample':>13} {'vs 93 us':>8}")
    ok, marginal = True, {}
    for profile, rate in COST_RUNS:
        fd = profile != 'classic'
        short = run(rate, 2.0, False, profile, fd)
        m = run(rate, duration, False, profile, fd)
        ok &= m['completed'] and m['lost'] == 0 and m['samples'] >= m['expected']
        us = (m['wall'] - short['wall']) / (m['samples'] - short['samples']) * 1e6
        marginal[(profile, rate)] = us
        print(f"{profile:>8} {rate:6.0f} {m['samples']:8d} {m['lost']:5d} {m['wall']:7.2f} {m['realtime']:11.2f} "
              f"{m['wall_us']:9.1f} {us:18.1f} {m['cpu_us']:13.1f} {TODAY_US / us:7.1f}x", flush=True)
    for rate in (1000.0, 2000.0):
        if ('single', rate) in marginal and ('packed', rate) in marginal:
            print(f'  at {rate:.0f} Hz: packed {marginal[("packed", rate)]:.1f} us vs single '
                  f'{marginal[("single", rate)]:.1f} us per sample '
                  f'({marginal[("single", rate)] / marginal[("packed", rate)]:.1f}x)')
    print()
    return ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=60.0, help='program length [s] (default 60)')
    ap.add_argument('--paced', type=float, nargs='*', default=[],
                    help='also run these rates paced (real time, packed frames on the timed CAN FD bus)')
    ap.add_argument('--data-bitrate', type=int, default=5_000_000,
                    help='CAN FD data bitrate of the paced runs [bit/s] (default 5000000; 8000000: FD 1/8)')
    args = ap.parse_args(argv)
    bus_profiles([500.0, 1000.0, 2000.0, 5000.0, 10000.0, 20000.0])
    run(1000.0, 1.0, False, 'packed')   # warm-up: imports, model set-up, DBC load are not per-sample costs
    ok = cost_table(args.duration)
    if args.paced:
        print(f'paced runs on the simulated CAN FD 1/{args.data_bitrate / 1e6:g} Mbit/s bus with bit timing, packed '
              f'frames, driver and simulated controller in this one process (one interpreter lock), '
              f'{args.duration:g} s program')
        print(f"{'rate':>7} {'samples':>8} {'lost':>5} {'late':>5} {'bad':>4} {'bus load':>8} {'expected':>8} "
              f"{'tx dropped':>10} {'cpu us/sample':>13}")
    for rate in args.paced:
        m = run(rate, args.duration, True, 'packed', data_bitrate=args.data_bitrate)
        ok &= m['completed'] and m['lost'] == 0 and m['samples'] >= m['expected']
        print(f"{m['rate']:7.0f} {m['samples']:8d} {m['lost']:5d} {m['late']:5d} {m['malformed']:4d} "
              f"{m['load'] * 100:7.1f}% {m['expected_load'] * 100:7.1f}% {m['tx_dropped']:10d} {m['cpu_us']:13.1f}",
              flush=True)
        if not m['completed']:
            print(f"        not completed: {m['message']}")
    print('zero lost frames, all runs complete' if ok else 'FAILED: lost frames or incomplete run')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
