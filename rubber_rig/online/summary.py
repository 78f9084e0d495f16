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

"""What a run of a test program showed, per program block: the table of steady cycles (measured next to the model)
and its summary files (JSON and Markdown beside the recording). ROS-free: ``rubber-rig bench`` feeds it the
element_model's cycle metrics; anything with the same fields (measured/model k_dyn, c_eq, ... per cycle) works.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np


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
        """Measured amplitude in the program's sense (first harmonic for sines, half peak-valley for triangles
        and squares: WaveformType.cycle_amplitude).
        """
        return blk.type.cycle_amplitude(c.amplitude, c.peak_amplitude)

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
        """Rows of block b as its waveform's summary says: one at its frequency ('steady'), one per frequency band
        of a sweep ('bands'), none otherwise.
        """
        blk = self.blocks[b]
        cycles = self.cycles.get(b, [])
        if blk.type.summary == 'steady':
            cyc = [c for c in cycles if self._amplitude(blk, c) >= 0.9 * blk.amplitude
                   and abs(c.frequency - blk.frequency) <= 0.1 * blk.frequency]
            rows = [self._row(b, blk.name, blk.frequency, cyc[len(cyc) // 2:] if len(cyc) > 1 else cyc)]
        elif blk.type.summary == 'bands':
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
    events = summary.get('events', [])
    lines += ['', f'## Detector events ({len(events)})', '']
    if events:
        lines += ['| block | cycle | program cycle | detector | action | value | reference | threshold | units |',
                  '|---|---|---|---|---|---|---|---|---|']
        lines += [f"| {e['block_index']} {e['block_name']} | {e['cycle']} | {e['program_cycle']} | {e['detector']} "
                  f"({e['kind']}) | {e['action']} | {e['value']:.6g} | {e['reference']:.6g} | {e['threshold']:.6g} | "
                  f"{e['units']} |" for e in events]
    else:
        lines.append('No detector tripped.')
    mpath.write_text('\n'.join(lines) + '\n')
    return jpath, mpath
