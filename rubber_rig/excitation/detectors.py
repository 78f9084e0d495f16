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

"""Detectors: the program's own judges of whether the specimen still is the specimen it was.

A program declares them in its YAML (``detectors:`` for the whole program, or in a block for that block); the
excitation node evaluates them on every cycle the element model measures (and the end-of-test triggers on every
sample batch) and acts on a trip. Each detector has an ``action``:

- ``record``: an event on the ``events`` topic (so in the recording and the report), nothing else;
- ``warn``: the event, a warning in the log and the diagnostics;
- ``hold``: the event, and the program holds at the block mean (resumable: ``excitation/hold`` false);
- ``end``: the event, and the program ends with the ramp to rest.

Types (``threshold`` is what trips it; all are judged only on *steady* cycles, inside a block's full-amplitude
part, so tapers and approach ramps never trip them):

- ``residual``: RMS of measured - model force over a cycle above ``threshold`` x the expected residual. The
  expected residual is the block's own stabilised value (median over ``reference_cycles`` cycles after
  ``settle_cycles``), at least the declared ``noise`` [N] and at least ``floor`` x the block's force amplitude
  (a perfect model on a quiet load cell must not make a tiny residual the yardstick).
- ``stiffness_change``: ``quantity`` (k_dyn, c_eq or loss_angle) of the cycle against a ``reference``:
  ``program`` (default) the specimen's stabilised ratio to the element model over the program's first steady
  cycles, so one reference serves every block and a change between blocks is seen; ``stabilised`` the block's
  own stabilised value; ``model`` the element model's value for the same cycle. Trips when
  ``|value / reference - 1| > threshold`` (a fraction: 0.2 = +-20 %, the end of life of elastomer durability
  tests is commonly a 10-30 % stiffness drop).
- ``force_drift``: ``quantity`` mean or amplitude of the measured force against the block's stabilised value;
  ``threshold`` is a force ('2 kN') or, as a plain number, a fraction of the larger of the stabilised force
  amplitude and mean (a preload's mean force relaxes by a few per cent of it during a block).
- ``tracking``: the measured displacement amplitude and mean against the block's targets, after
  ``settle_cycles`` (the amplitude loop converges over the first cycles); trips when the larger error exceeds
  ``threshold`` x the target amplitude.
- ``cycle_count``: ``threshold`` full-amplitude cycles of the program (of the block, in a block) are done.
- ``elapsed_time``: ``threshold`` of rig time since the program started ('2 h').

- ``model_fit``: the online model against the specimen over the program's first steady cycles (a
  ``model_mismatch`` event; the residual detectors recalibrated or declared blind); ``load_cell``: load-cell
  faults told from specimen changes by the cycle's signature, and the cause every trip is put down to. Both in
  :mod:`.diagnosis`, whose docstring says how.

``consecutive``: cycles in a row over the threshold before it trips (default 1: a crack is acted on one cycle
after it happens). A detector trips once per block; after a hold and resume it is armed again. The cycles a
reference is gathered from are judged against it once it is set (a residual's reference is their smallest
value), so a change while the reference is gathered trips too, on the cycle the reference is complete.
"""
from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, field

import numpy as np

from .detector_specs import (
    DIAGNOSTICS,
    SEVERITY,
    TRIGGERS,
    UNITS,
    DetectorSpec,
)
from .diagnosis import CAUSE_OF_TYPE, LoadCellJudge, ModelFit, ModelFitCheck
from .judged_cycles import BLIND_CYCLES, BLIND_SECONDS, Cycle, blind_for, cycle_of

__all__ = ['BLIND_CYCLES', 'BLIND_SECONDS', 'Cycle', 'Event', 'Monitor', 'blind_for', 'cycle_of', 'strongest']


@dataclass
class Event:
    """A detector tripped: what it saw, against what, and what it asks for."""

    detector: str
    kind: str
    block: int
    cycle: int
    program_cycle: int
    elapsed: float
    value: float
    reference: float
    threshold: float
    units: str
    action: str
    message: str
    sequence: int = 0              # rig sample sequence the event belongs to (after the cycle or batch judged)
    cause: str = ''                # diagnosis.CAUSES: what the event is put down to (DetectorEvent.cause)
    code: str = ''                 # finer: stuck | saturation | spikes | offset_jump | mean_step | changed | mismatch


@dataclass
class _BlockState:
    references: dict = field(default_factory=dict)   # detector name -> stabilised reference (float or tuple)
    samples: dict = field(default_factory=dict)      # detector name -> values gathered for the reference
    over: dict = field(default_factory=dict)         # detector name -> consecutive cycles over the threshold
    tripped: set = field(default_factory=set)
    seen: dict = field(default_factory=dict)         # detector name -> steady cycles judged (tracking's settle)


class Monitor:
    """Evaluates a program's detectors cycle by cycle and trigger by trigger; returns the Events."""

    def __init__(self, detectors: list[DetectorSpec]):
        self.detectors = list(detectors)
        self._blocks: dict[int, _BlockState] = {}
        self._program = _BlockState()      # references that serve every block (stiffness_change 'program')
        self.events: list[Event] = []
        # detector name -> the largest fraction of its threshold any judged cycle reached (1 = trips): the
        # margin a clean run leaves, what a threshold is chosen from (benchmarks/bench_detectors.py)
        self.peak: dict[str, float] = {}
        fit = next((d for d in self.detectors if d.type == 'model_fit'), None)
        cell = next((d for d in self.detectors if d.type == 'load_cell'), None)
        self.fit_check = ModelFitCheck(fit) if fit else None
        self.load_cell = LoadCellJudge(cell) if cell else None
        self.fit: ModelFit | None = None
        self.residual_mode = ''         # '' (as declared) | 'recalibrated' | 'blind' after a model mismatch

    @property
    def needs_cycles(self) -> bool:
        """Some detector judges measured cycles (not only the end-of-test triggers)."""
        return any(d.type not in TRIGGERS for d in self.detectors)

    @property
    def blind(self) -> str:
        """Why some cycle detectors judge nothing now ('' when they all judge): a model mismatch declared the
        residual detectors blind, or the load cell is stuck or clipped (until a resume).
        """
        why = []
        if self.residual_mode == 'blind':
            why.append('residual detectors declared blind after a model mismatch (model_fit on_mismatch: blind)')
        if self.load_cell is not None and self.load_cell.fault:
            why.append(f'load cell {self.load_cell.fault}: the specimen detectors judge nothing until a resume')
        return '; '.join(why)

    def rearm(self) -> None:
        """After a hold: every detector may trip again (references are kept: the block is the same block)."""
        for state in self._blocks.values():
            state.tripped.clear()
            state.over.clear()
        if self.load_cell is not None:
            self.load_cell.rearm()

    def _applies(self, d: DetectorSpec, block: int) -> bool:
        return d.block in (-1, block)

    def on_cycle(self, c: Cycle) -> list[Event]:
        """Judge one measured cycle with every cycle detector of its block (and the model_fit and load_cell
        diagnostics of the program, :mod:`.diagnosis`).
        """
        state = self._blocks.setdefault(c.block, _BlockState())
        out = []
        if not c.steady:
            return out
        if self.fit_check is not None:
            fit = self.fit_check.observe(c)
            if fit is not None:
                out += self._model_fit(self.fit_check.spec, c, fit)
        cell = self.load_cell
        # stuck or clipped: nothing the force says is judged until a resume (tracking judges the displacement)
        force_blind = cell is not None and bool(cell.fault)
        if cell is not None:
            c = cell.compensate(c)
        held = {d.name for d, _, _ in cell.held.trips} if cell is not None and cell.held else set()
        trips = []
        for d in self.detectors:
            if d.type in TRIGGERS or d.type in DIAGNOSTICS or not self._applies(d, c.block) \
                    or d.name in state.tripped or d.name in held or (force_blind and d.type != 'tracking'):
                continue
            if d.type == 'residual' and self.residual_mode == 'blind':
                continue
            judged = self._judge(d, c, state)
            if judged is None:
                continue
            value, reference, threshold, units, deviation = judged
            self.peak[d.name] = max(self.peak.get(d.name, 0.0), deviation / threshold if threshold else math.inf)
            n = state.over[d.name] = state.over.get(d.name, 0) + 1 if deviation > threshold else 0
            if n >= d.consecutive:
                trips.append((d, judged, c))
        if cell is None:
            for d, judged, tc in trips:
                out.append(self._release(d, judged, tc, c, CAUSE_OF_TYPE[d.type], '', ''))
            return out
        for v in [] if force_blind else cell.observe(c, [t for t in trips if t[0].type != 'tracking']):
            if v.cause == 'sensor':
                out.append(self._cell_event(cell.spec, c, v, cell.spec.action))
            elif v.code == 'mean_step' and not v.trips:
                out.append(self._cell_event(cell.spec, c, v, 'record'))
            for d, judged, tc in v.trips:
                out.append(self._release(d, judged, tc, c, v.cause, v.code, v.detail))
        # tracking judges the actuator, not the force: no load-cell verdict to wait for
        out += [self._release(d, j, tc, c, 'control', '', '') for d, j, tc in trips if d.type == 'tracking']
        return out

    def _release(self, d, judged, tripped_on: Cycle, c: Cycle, cause: str, code: str, detail: str) -> Event:
        """The Event of detector d's trip on cycle `tripped_on`, acted on at cycle c (later when the load cell
        held it back while it judged what followed).
        """
        value, reference, threshold, units, _ = judged
        state = self._blocks.setdefault(tripped_on.block, _BlockState())
        note = ''
        if tripped_on.program_cycle != c.program_cycle:
            note = f' (tripped on cycle {tripped_on.cycle}, decided on cycle {c.cycle})'
        if detail:
            note += f'; {detail}'
        if d.type == 'residual' and self.residual_mode == 'recalibrated':
            note += '; first-harmonic residual of the recalibrated model'
        return self._trip(d, state, c.block, c.cycle, c.program_cycle, c.elapsed, value, reference, threshold, units,
                          c.end_sequence, cause=cause, code=code, note=note)

    def _cell_event(self, spec, c: Cycle, v, action: str) -> Event:
        """The load_cell detector's event of verdict v (a sensor fault, or a step it could not put down)."""
        blind = ' The specimen detectors are blind until the program is resumed.' \
            if v.code in ('stuck', 'saturation') else ''
        if v.cause != 'sensor':
            blind = ' No specimen detector tripped on it.'
        msg = (f"[cause {v.cause}/{v.code}] detector '{spec.name}' (load_cell) in block {c.block}, cycle {c.cycle}: "
               f"{v.detail}.{blind} Action {action}")
        event = Event(spec.name, 'load_cell', c.block, int(c.cycle), int(c.program_cycle), float(c.elapsed),
                      float(v.value), float(v.reference), float(v.threshold), v.units, action, msg,
                      int(c.end_sequence), v.cause, v.code)
        self.events.append(event)
        return event

    def _model_fit(self, spec, c: Cycle, fit: ModelFit) -> list[Event]:
        """The model_mismatch event (and the residual detectors recalibrated or declared blind), or nothing."""
        self.fit = fit
        if fit.fits:
            return []
        residuals = [d for d in self.detectors if d.type == 'residual']
        names = ', '.join(repr(d.name) for d in residuals) or 'none'
        if spec.on_mismatch == 'blind':
            self.residual_mode = 'blind'
            then = f'residual detectors ({names}) declared blind for this program'
        else:
            self.residual_mode = 'recalibrated'
            for state in [self._program, *self._blocks.values()]:
                for d in residuals:
                    state.samples.pop(d.name, None)
                    state.references.pop(d.name, None)
                    state.over.pop(d.name, None)
            sensitivity = ', '.join(f'{d.name!r} about {d.threshold * d.floor * math.sqrt(2):.1%}' for d in residuals)
            then = (f'residual detectors ({names}) recalibrated: they judge the first-harmonic residual of the model '
                    f'scaled by the measured complex-stiffness ratio {abs(fit.rho):.4f} at '
                    f'{math.degrees(cmath.phase(fit.rho)):+.2f} deg, with references gathered anew (detect a change '
                    f'of |K*| of {sensitivity or "-"} where their floor sets the yardstick)')
        msg = (f"[cause model/mismatch] detector '{spec.name}' (model_fit) in block {c.block}, cycle {c.cycle}: the "
               f'online model does not fit the specimen over its first {fit.cycles} steady cycles: measured/model '
               f'K_dyn {fit.k_ratio:.4f} (tolerance 1 +- {fit.k_tolerance:.3f}), C_eq {fit.c_ratio:.4f} (tolerance '
               f'1 +- {fit.c_tolerance:.3f}); {then}; action {spec.action}')
        event = Event(spec.name, 'model_mismatch', c.block, int(c.cycle), int(c.program_cycle), float(c.elapsed),
                      fit.k_ratio, 1.0, fit.k_tolerance, '-', spec.action, msg, int(c.end_sequence), 'model',
                      'mismatch')
        self.events.append(event)
        return [event]

    def on_progress(self, block: int, block_cycles: int, program_cycles: int, elapsed: float,
                    sequence: int = 0) -> list[Event]:
        """Judge the end-of-test triggers: full-amplitude cycles done in the block and the program, rig time [s],
        at rig sample `sequence`.
        """
        state = self._blocks.setdefault(block, _BlockState())
        out = []
        for d in self.detectors:
            if d.type not in TRIGGERS or not self._applies(d, block) or d.name in state.tripped:
                continue
            if d.type == 'cycle_count':
                count = block_cycles if d.block >= 0 else program_cycles
                if count >= d.threshold:
                    out.append(self._trip(d, state, block, block_cycles, program_cycles, elapsed, count, math.nan,
                                          d.threshold, 'cycles', sequence))
            elif elapsed >= d.threshold:
                out.append(self._trip(d, state, block, block_cycles, program_cycles, elapsed, elapsed, math.nan,
                                      d.threshold, 's', sequence))
        return out

    def _trip(self, d, state, block, cycle, program_cycle, elapsed, value, reference, threshold, units,
              sequence, cause: str = '', code: str = '', note: str = '') -> Event:
        state.tripped.add(d.name)
        if d.type in TRIGGERS:
            what = f'{value:.6g} {units} reached (threshold {threshold:.6g} {units})'
        elif d.type == 'residual':
            what = f'residual RMS {value:.6g} N, {threshold / reference:g} x the expected {reference:.6g} N exceeded'
        else:
            change = f' ({value / reference - 1:+.1%})' if reference else ''
            what = (f'{value:.6g} {units} against {reference:.6g} {units}{change}, allowed deviation '
                    f'{threshold:.6g} {units}')
            if d.reference == 'program':
                what += " (reference: the specimen's stabilised ratio to the model, at this cycle's model value)"
        cause = cause or CAUSE_OF_TYPE[d.type]
        label = f"[cause {cause}{'/' + code if code else ''}] "
        msg = f"{label}detector '{d.name}' ({d.type}) in block {block}, cycle {cycle}: {what}{note}; action {d.action}"
        event = Event(d.name, d.type, block, int(cycle), int(program_cycle), float(elapsed), float(value),
                      float(reference), float(threshold), units, d.action, msg, int(sequence), cause, code)
        self.events.append(event)
        return event

    def _stabilised(self, d, state, value, reduce=np.median):
        """(reference, the cycles it was gathered from) of detector d: the reduced values of its
        ``reference_cycles`` after ``settle_cycles``. The cycles are returned once, on the cycle that completes
        the reference (so the caller judges them too), () after that; (None, ()) while gathering.
        """
        if d.name in state.references:
            return state.references[d.name], ()
        got = state.samples.setdefault(d.name, [])
        if not np.all(np.isfinite(value)):           # a cycle the model or the analysis could not judge
            return None, ()
        got.append(value)
        if len(got) < d.settle_cycles + d.reference_cycles:
            return None, ()
        window = got[d.settle_cycles:]
        ref = reduce(np.asarray(window, dtype=float), axis=0)
        state.references[d.name] = tuple(float(r) for r in ref) if np.ndim(ref) else float(ref)
        return state.references[d.name], window

    def _judge(self, d, c: Cycle, state):
        """(value, reference, threshold, units, deviation) of detector d on cycle c, or None (not armed yet, or
        the cycle lacks what it needs); it trips when deviation > threshold. On the cycle that completes a
        reference, the worst of its cycles is judged.
        """
        m = c.measured
        if d.type == 'residual':
            residual = c.residual_rms
            if self.residual_mode == 'recalibrated':
                residual = self.fit.first_harmonic_residual(c)
            ref, window = self._stabilised(d, state, (residual, m.get('force_amplitude', math.nan)), np.min)
            if ref is None or not math.isfinite(residual):
                return None
            expected = max(ref[0], d.noise, d.floor * ref[1])
            worst = max([residual] + [w[0] for w in window])
            return worst, expected, d.threshold * expected, 'N', worst
        if d.type == 'stiffness_change':
            value, model = m.get(d.quantity, math.nan), c.model.get(d.quantity, math.nan)
            if d.reference == 'model':
                ref, window = model, ()
            elif d.reference == 'program':
                ratio, window = self._stabilised(d, self._program, value / model if model else math.nan)
                if ratio is None:
                    return None
                ref, window = ratio * model, [w * model for w in window]
            else:
                ref, window = self._stabilised(d, state, value)
                if ref is None:
                    return None
            if not (math.isfinite(value) and math.isfinite(ref)) or ref == 0:
                return None
            worst = max([value, *window], key=lambda v: abs(v - ref))
            bound = d.threshold * abs(ref)
            return worst, ref, bound, UNITS[d.quantity], abs(worst - ref)
        if d.type == 'force_drift':
            value = m.get('force_mean' if d.quantity == 'mean' else 'force_amplitude', math.nan)
            ref, window = self._stabilised(d, state, (value, m.get('force_amplitude', math.nan),
                                                      abs(m.get('force_mean', math.nan))))
            if ref is None or not math.isfinite(value):
                return None
            # a fraction of the larger of the force amplitude and the preload: a preloaded specimen's mean
            # force relaxes by a few per cent of the preload during a block, which is not a departure
            bound = d.threshold if d.threshold_units == 'N' else d.threshold * max(ref[1], ref[2])
            worst = max([value] + [w[0] for w in window], key=lambda v: abs(v - ref[0]))
            return worst, ref[0], bound, 'N', abs(worst - ref[0])
        if d.type == 'tracking':
            if not (math.isfinite(c.target_amplitude) and c.target_amplitude > 0):
                return None
            state.seen[d.name] = state.seen.get(d.name, 0) + 1
            if state.seen[d.name] <= d.settle_cycles:     # the amplitude loop converges over the first cycles
                return None
            error = max(abs(c.amplitude - c.target_amplitude), abs(c.mean - c.target_mean))
            bound = d.threshold * c.target_amplitude
            return error, c.target_amplitude, bound, 'm', error
        return None


def strongest(events: list[Event]) -> Event | None:
    """The event whose action goes furthest (end > hold > warn > record), or None."""
    return max(events, key=lambda e: SEVERITY[e.action], default=None)
