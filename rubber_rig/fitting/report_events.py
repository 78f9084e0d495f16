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

"""The report's view of what happened during the test: K_dyn and C_eq cycle by cycle as the element model
measured them online (a durability test's stiffness curve), the detector events as markers, and their table.
"""
from __future__ import annotations

import html

import numpy as np

ACTION_COLOURS = {'record': '0.45', 'warn': 'C1', 'hold': 'C3', 'end': 'k'}


def event_cycle(cycles: dict, event: dict) -> int:
    """Measured-cycle number (1 = the first recorded) an event belongs to; 0 when it lies before them."""
    return int(np.searchsorted(cycles['end_sequence'], int(event['sequence']), side='left')) + 1 \
        if event.get('sequence') else 0


def fig_cycles(run, plt):
    """K_dyn [kN/mm] and C_eq [kN s/m] of every cycle the element model measured online (and the model's) over
    the cycle number, with the detector events as vertical lines; None without recorded cycle metrics.
    """
    c = getattr(run, 'cycles', None)
    if not c or not c['k_dyn'].size:
        return None
    n = np.arange(1, c['k_dyn'].size + 1)
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    panels = ((axes[0], 'k_dyn', 1e-6, 'K_dyn [kN/mm]'), (axes[1], 'c_eq', 1e-3, 'C_eq [kN s/m]'))
    for ax, key, scale, label in panels:
        ax.plot(n, c[key + '_model'] * scale, lw=1.0, color='C3', label='model (online)')
        ax.plot(n, c[key] * scale, '.', ms=2.5, color='C0', label='measured')
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    for e in getattr(run, 'events', []):
        x = event_cycle(c, e)
        for ax in axes:
            ax.axvline(x, color=ACTION_COLOURS.get(e['action'], 'C4'), lw=1.2, ls='--')
        axes[0].annotate(f"{e['detector']} ({e['action']})", (x, 1.0), xycoords=('data', 'axes fraction'),
                         rotation=90, va='top', ha='right', fontsize=8)
    axes[0].legend(fontsize=8, loc='lower left')
    axes[1].set_xlabel('measured cycle (tapers and every block counted, in recording order)')
    axes[0].set_title('Cycle by cycle, as measured online (dashed: detector events)')
    fig.tight_layout()
    return fig


def mark_events(axes, events: list, dt: float) -> None:
    """Vertical lines at the samples the events belong to (time axis [s])."""
    for e in events:
        if e['sample'] >= 0:
            for ax in axes:
                ax.axvline(e['sample'] * dt, color=ACTION_COLOURS.get(e['action'], 'C4'), lw=1.2, ls='--')


def events_html(events: list) -> list[str]:
    """The 'Detector events' section of the report (a sentence when there were none)."""
    esc = html.escape
    out = [f'<h2>Detector events ({len(events)})</h2>']
    if not events:
        return out + ['<p>No detector tripped while this was recorded (or the recording has no events topic).</p>']
    head = ['block', 'cycle', 'program cycle', 'rig time [s]', 'detector', 'cause', 'action', 'message']
    out.append('<table class="blocks"><tr>' + ''.join(f'<th>{h}</th>' for h in head) + '</tr>')
    for e in events:
        cells = [f"{e['block_index']} {esc(e['block_name'])}", str(e['cycle']), str(e['program_cycle']),
                 f"{e['elapsed']:.3f}", esc(f"{e['detector']} ({e['kind']})"),
                 esc('/'.join(x for x in (e.get('cause', ''), e.get('code', '')) if x) or '-'), esc(e['action']),
                 esc(e['message'])]
        out.append('<tr>' + ''.join(f'<td>{c}</td>' for c in cells) + '</tr>')
    return out + ['</table>']
