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

"""Pre-start check benchmark: parsing and Limits.check_program of the longest programs a request may load
(24 h of rig time, blocks.MAX_PROGRAM_DURATION) must stay well below the 0.5 s target at any accepted sample
rate, since the excitation node checks a program inside its service and action callbacks.

    .venv/bin/python benchmarks/bench_checks.py            # 1 kHz and 10 kHz
    .venv/bin/python benchmarks/bench_checks.py --rate 20000

Exit status 1 if any check takes longer than the target.
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from rubber_rig.excitation import Program  # noqa: E402
from rubber_rig.excitation.limits import check_program, element_force_model  # noqa: E402
from rubber_rig.excitation.program import MAX_BLOCKS  # noqa: E402
from rubber_rig.safety import Limits  # noqa: E402

TARGET = 0.5   # [s]


def programs():
    """(label, YAML) of long programs: one 24 h sine, a 24 h mix of blocks, the most blocks allowed."""
    day = 24 * 3600
    yield 'one 24 h sine at 5 Hz', (f'name: day\nblocks:\n  - {{waveform: sine, frequency: 5 Hz, amplitude: 1 mm, '
                                    f'cycles: {5 * day - 4}, taper_cycles: 2}}\n')
    per = day / 6 - 1
    yield '24 h of sine, triangle, square, sweep, ramp, hold', f"""name: mix
blocks:
  - {{waveform: sine, frequency: 10 Hz, amplitude: 1 mm, cycles: {int(per * 10) - 4}, taper_cycles: 2}}
  - {{waveform: triangle, frequency: 1 Hz, amplitude: 1 mm, cycles: {int(per) - 4}, taper_cycles: 2}}
  - {{waveform: square, frequency: 1 Hz, rate: 20 mm/s, amplitude: 1 mm, cycles: {int(per) - 4}, taper_cycles: 2}}
  - {{waveform: sweep_log, f_start: 1 Hz, f_end: 50 Hz, duration: {per - 10:.0f} s, amplitude: 0.3 mm}}
  - {{waveform: ramp, target: -1 mm, duration: {per:.0f} s}}
  - {{waveform: hold, duration: {per:.0f} s}}
"""
    n = int(MAX_BLOCKS ** 0.5)
    amps = ', '.join(f'{0.1 + 0.5 * i / n:.4f} mm' for i in range(n))
    freqs = ', '.join(f'{1 + 40 * i / n:.3f} Hz' for i in range(n))
    yield f'{n * n} blocks of 8.6 s (grid)', (f'name: grid\nblocks:\n  - {{waveform: sine, amplitude: [{amps}], '
                                              f'frequency: [{freqs}], cycles: 8, taper_cycles: 2}}\n')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--rate', type=float, action='append', help='sample rate [Hz] (repeatable; default 1k, 10k)')
    args = ap.parse_args(argv)
    rates = args.rate or [1000.0, 10000.0]
    limits = Limits(force_model=element_force_model())
    worst = 0.0
    for label, text in programs():
        t0 = time.perf_counter()
        prog = Program.from_yaml_text(text)
        parse = time.perf_counter() - t0
        for fs in rates:
            t0 = time.perf_counter()
            check_program(limits, prog, fs)
            check = time.perf_counter() - t0
            worst = max(worst, parse + check)
            print(f'{label:52s} {fs:7.0f} Hz  {prog.duration(fs) / 3600:5.2f} h  {prog.n_samples(fs):11d} samples  '
                  f'parse {parse * 1e3:7.1f} ms  check {check * 1e3:7.1f} ms')
    print(f'worst parse + check {worst * 1e3:.1f} ms (target {TARGET * 1e3:.0f} ms)')
    return 0 if worst <= TARGET else 1


if __name__ == '__main__':
    sys.exit(main())
