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

"""The scenario harness on simulated time (rubber_rig.session.scenario): how much faster than real time it runs
at 1 kHz, what its scenarios measure, and what the excitation's lead_time trades (stall tolerance against
amplitude-loop latency).

    .venv/bin/python benchmarks/bench_scenario.py              # speed and the scenarios
    .venv/bin/python benchmarks/bench_scenario.py --lead       # the lead_time table as well (about a minute more)

Speed is rig time over the CPU time of this process (time.process_time), one BLAS thread; the machine's load
average is printed with it (a figure measured under load says so).
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

from rubber_rig.excitation.program import Program  # noqa: E402
from rubber_rig.rig.sim.damage import sample_at_cycle  # noqa: E402
from rubber_rig.session.program_session import LEAD_TIME  # noqa: E402
from rubber_rig.session.scenario import Scenario  # noqa: E402

SINE = {'name': 'sine', 'defaults': {'taper_cycles': 2},
        'blocks': [{'name': 's10', 'waveform': 'sine', 'frequency': '10 Hz', 'amplitude': '1 mm', 'cycles': 60}]}
SHORT_HIGH = {'name': 'short_high', 'defaults': {'taper_cycles': 2}, 'blocks': [
    {'name': 'warm', 'waveform': 'sine', 'amplitude': '1 mm', 'frequency': '5 Hz', 'cycles': 10},
    {'name': 's30', 'waveform': 'sine', 'amplitude': '0.5 mm', 'frequency': '30 Hz', 'cycles': 40}]}


def timed(make):
    """(outcome, CPU seconds) of one scenario run."""
    t = time.process_time()
    o = make().run()
    return o, time.process_time() - t


def delay(o, cycle: float) -> str:
    i = sample_at_cycle(o.displacement, cycle)
    d = o.first_departure(int(o.sequence[i])) if i >= 0 else None
    return f'{(d - int(o.sequence[i])) / 100:.2f} cycles' if d is not None else 'never left the program'


CASES = [
    ('undisturbed, 60 cycles 10 Hz', lambda: Scenario(Program.from_dict(SINE)), lambda o: o.reason),
    ('excitation stalled 0.5 s at 2.0 s', lambda: Scenario(Program.from_dict(SINE)).stall('excitation', 2.0, 0.5),
     lambda o: o.reason),
    ('excitation dead at 2.0 s', lambda: Scenario(Program.from_dict(SINE)).stall('excitation', 2.0),
     lambda o: f'ended {o.ended_at - 2.0:.3f} s after, at {o.final_position * 1e3:.3f} mm'),
    ('controller frozen at 1.5 s', lambda: Scenario(Program.from_dict(SINE)).stall('controller', 1.5),
     lambda o: f'ended {o.ended_at - 1.5:.3f} s after: {o.faults[:1]}'),
    ('operator hold 1 s at 2.5 s', lambda: Scenario(Program.from_dict(SINE)).hold(2.5, 1.0),
     lambda o: f'{o.reason}; cycles {[b.cycles_measured for b in o.blocks]}'),
    ('crack at cycle 30', lambda: Scenario(Program.from_dict(SINE), {'sim': {'damage': [
        {'type': 'crack', 'cycle': 30, 'loss': 0.3, 'damping': 2000.0}]}}, amplitude_control=True),
     lambda o: f'{o.reason[:40]}...; left the program {delay(o, 30)} after onset'),
    ('slip 0.3 mm at cycle 30', lambda: Scenario(Program.from_dict(dict(SINE, detectors=[
        {'type': 'residual', 'action': 'record'}])), {'sim': {'damage': [
            {'type': 'slip', 'cycle': 30, 'offset': 0.3e-3}]}}, amplitude_control=True),
     lambda o: f'{o.reason[:40]}...; left the program {delay(o, 30)} after onset'),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--lead', action='store_true', help='also the lead_time table')
    args = ap.parse_args()
    print(f'load average at start: {os.getloadavg()[0]:.2f}')
    print('| scenario | rig time [s] | CPU [s] | x real time | outcome |\n|---|---|---|---|---|')
    rig = cpu = 0.0
    for name, make, say in CASES:
        o, c = timed(make)
        span = (o.sequence[-1] - o.sequence[0] + 1) / 1000.0
        rig, cpu = rig + span, cpu + c
        print(f'| {name} | {span:.2f} | {c:.2f} | {span / c:.1f} | {say(o)} |')
    print(f'| all | {rig:.1f} | {cpu:.1f} | {rig / cpu:.1f} | |')
    if args.lead:
        print(f'\nlead_time (default {LEAD_TIME} s): the longest excitation stall ridden out, and the amplitude of a '
              '30 Hz block of 40 cycles after a 5 Hz block (amplitude control on)')
        print('| lead_time [s] | stall ridden out [s] | 30 Hz block amplitude error |\n|---|---|---|')
        for lead in (0.5, 0.8, 1.0, 1.2):
            longest = 0.0
            for stall in [x / 100 for x in range(10, int(lead * 100), 5)]:
                if not Scenario(Program.from_dict(SINE), lead_time=lead).stall('excitation', 2.0, stall).run() \
                        .completed:
                    break
                longest = stall
            o = Scenario(Program.from_dict(SHORT_HIGH), lead_time=lead, amplitude_control=True).run()
            b = o.blocks[1]
            print(f'| {lead} | {longest:.2f} | {(b.achieved_amplitude / b.target_amplitude - 1) * 100:+.2f} % |')
    print(f'load average at end: {os.getloadavg()[0]:.2f}')


if __name__ == '__main__':
    main()
