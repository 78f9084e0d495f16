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

"""Rig benchmark: 60 s programs at 1 kHz and 5 kHz through driver + simulated rig on the in-process python-can
virtual bus (every sample: setpoint frame out, feedback frame back, both DBC-encoded and decoded, seed-000
specimen). Reports samples, lost frames, achieved rate and per-sample cost.

    .venv/bin/python benchmarks/bench_rig.py                 # fast (as fast as possible) at 1 kHz and 5 kHz
    .venv/bin/python benchmarks/bench_rig.py --paced 1000    # also a real-time run at 1 kHz (takes 60 s)
    .venv/bin/python benchmarks/bench_rig.py --duration 10   # shorter

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
from rubber_rig.rig import run_program  # noqa: E402
from rubber_rig.rig.can.timing import protocol_load  # noqa: E402


def program(duration: float) -> Program:
    """A sine program of `duration` s: 5 Hz, 0.5 mm, 1 taper cycle in and out."""
    cycles = int(round(duration * 5)) - 2
    return Program.from_yaml_text(f'name: bench_{duration:g}s\nblocks:\n  - {{waveform: sine, frequency: 5 Hz, '
                                  f'amplitude: 0.5 mm, cycles: {cycles}, taper_cycles: 1}}\n')


def run(rate: float, duration: float, paced: bool) -> dict:
    prog = program(duration)
    # the paced simulator shares this process (and its GIL) with the host loop on a loaded machine: a wall-clock
    # heartbeat watchdog of 1 s keeps a starved thread from aborting the run (hardware has its own CPU)
    cfg = {'paced': paced, 'sample_rate': rate, 'watchdog_timeout': 1.0 if paced else 0.25}
    c0, t0 = time.process_time(), time.perf_counter()
    r = run_program(prog, cfg)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    n = int(r.sequence.size)
    st = r.final_status
    return dict(rate=rate, mode='paced' if paced else 'fast', samples=n, expected=prog.n_samples(rate),
                lost=st.frames_lost, late=st.frames_late, malformed=st.frames_malformed, completed=r.completed,
                wall=wall, achieved=n / wall, wall_us=wall / n * 1e6, cpu_us=cpu / n * 1e6,
                realtime=(n / rate) / wall, message=r.message)


PROFILES = (('classic 500 kbit/s', 500_000, None, False), ('classic 1 Mbit/s', 1_000_000, None, False),
            ('FD 1/5 Mbit/s', 1_000_000, 5_000_000, True), ('FD 1/8 Mbit/s', 1_000_000, 8_000_000, True))


def bus_profiles(rates) -> None:
    """What the protocol (the DBC) needs of each bus profile: load at each rate (worst-case bit stuffing) and the
    highest rate at 50 %, 70 % and 100 % load.
    """
    print('bus load of the protocol (rubber_rig.rig.can.timing, worst-case bit stuffing):')
    print(f"{'profile':>20} " + ' '.join(f'{r:>8.0f}' for r in rates) + f" {'@50 %':>8} {'@70 %':>8} {'full':>8}")
    for name, bitrate, data_bitrate, fd in PROFILES:
        try:
            loads = [protocol_load(r, bitrate, data_bitrate, fd=fd) for r in rates]
        except ValueError as exc:
            print(f'{name:>20}  cannot carry it: {str(exc).split(": ", 1)[1]}')
            continue
        top = loads[0]
        print(f'{name:>20} ' + ' '.join(f'{ld.load * 100:7.0f}%' for ld in loads)
              + f' {top.rate_at(0.5):8.0f} {top.rate_at(0.7):8.0f} {top.max_rate:8.0f}')
    print()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=60.0, help='program length [s] (default 60)')
    ap.add_argument('--rates', type=float, nargs='*', default=[1000.0, 3000.0],
                    help='sample rates [Hz] (the default bus, CAN FD 1/5 Mbit/s, carries at most ~3.4 kHz at 70 %%)')
    ap.add_argument('--paced', type=float, nargs='*', default=[], help='also run these rates paced (real time)')
    args = ap.parse_args(argv)
    bus_profiles(sorted(set(args.rates) | set(args.paced) | {1000.0, 2000.0, 5000.0, 10000.0}))
    runs = [(r, False) for r in args.rates] + [(r, True) for r in args.paced]
    print(f'rig benchmark: {args.duration:g} s sine program, driver + simulated rig (seed 000) on the in-process '
          f'virtual bus, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}')
    print(f"{'rate':>7} {'mode':>5} {'samples':>8} {'lost':>5} {'late':>5} {'bad':>4} {'wall s':>7} "
          f"{'achieved/s':>10} {'x real time':>11} {'us/sample':>9} {'cpu us/sample':>13}")
    run(1000.0, 1.0, False)   # warm-up: imports, model set-up, DBC load are not per-sample costs
    ok = True
    for rate, paced in runs:
        m = run(rate, args.duration, paced)
        ok &= m['completed'] and m['lost'] == 0 and m['samples'] >= m['expected']
        print(f"{m['rate']:7.0f} {m['mode']:>5} {m['samples']:8d} {m['lost']:5d} {m['late']:5d} "
              f"{m['malformed']:4d} {m['wall']:7.2f} {m['achieved']:10.0f} {m['realtime']:11.2f} "
              f"{m['wall_us']:9.1f} {m['cpu_us']:13.1f}", flush=True)
        if not m['completed']:
            print(f"        not completed: {m['message']}")
    print('zero lost frames, all runs complete' if ok else 'FAILED: lost frames or incomplete run')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
