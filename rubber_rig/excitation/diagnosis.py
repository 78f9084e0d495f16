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

"""What a detector trip means: does the model fit the specimen, is a change the specimen's or the load cell's.

ROS-free; the Monitor in :mod:`.detectors` runs both on every steady cycle.

``model_fit``: over the program's first steady cycles (``settle_cycles`` skipped, ``reference_cycles`` judged)
the median measured/model ratios of K_dyn and C_eq (seed 000 Eq. 2, 27) are compared with 1; the tolerance of
each is the declared one (``threshold`` for K_dyn, ``c_eq_threshold`` for C_eq) widened by 3 standard errors of
the median (1.2533 x the robust standard deviation / sqrt(n)), so a noisy load cell does not call a good model
wrong. Outside it, an event of kind ``model_mismatch`` (cause ``model``) carries both ratios and tolerances, and
the residual detectors are, by ``on_mismatch``:

- ``recalibrate`` (default): they judge the *first-harmonic residual* of the model corrected by the measured
  complex-stiffness ratio rho = median(K*/K*_model) (K* = K_dyn exp(i delta), Eq. 2, 26):
  r1 = |K* - rho K*_model| x0 / sqrt(2), an RMS force [N], with their references gathered anew. A wrong model's
  misfit is then no longer the yardstick, and the event says which change in |K*| the residual now detects.
- ``blind``: they are suspended, and the event says so; nothing is silently blind.

``load_cell``: a signature of every steady cycle against its reference: the ratios to the model of K_dyn and C_eq,
the mean-force offset from the model, the force amplitude against the expected one and the shape factor (half peak-
to-peak force / (K_dyn x0): a clipped cycle loses its peaks, not its first harmonic), against the block's own
recent cycles (a model's misfit differs between operating points; a change between blocks is the program-
referenced stiffness_change's to see, released with cause ``specimen`` like every trip made before the block's
reference is complete). A cycle is ``stuck`` (force amplitude below 1 % of the expected), ``saturated`` (shape
factor down by more than 1 %), ``distorted`` (up by more than 10 %), ``changed`` (K_dyn or C_eq ratio off by more
than 3 % or 10 %), ``step`` (mean force off by more than ``threshold`` x the expected force amplitude) or
``normal``; every bound is at least 5 robust standard deviations of the reference cycles. A specimen detector's
trip on a cycle that is not plainly the specimen's (stiffness off by more than 9 %), and not like the cycles before
it (a gradual change such as fatigue is the specimen's at once), is held back for ``confirm_cycles`` and decided by
what follows:

- stuck (at once) or saturated (two cycles in a row): a load-cell fault (cause ``sensor``, code ``stuck`` or
  ``saturation``): the load_cell event with its own action, and the specimen detectors are blind (the event says
  so) until the program is resumed;
- the next cycle normal again (no lasting change of stiffness, loop or mean): ``spikes`` (cause ``sensor``) if a
  specimen detector had tripped on it, nothing otherwise;
- a distorted cycle (shape factor up by more than 10 %: a spike, a reading frozen part of the way) is held too;
- a lasting stiffness or loop change: the held trips are released with cause ``specimen``, and the block's
  signature is learnt afresh;
- a step of the mean force with stiffness and loop unchanged: a load-cell offset stays flat, while a fixture
  slip is a displacement step the viscoelastic specimen relaxes from (its mean force creeps back by a few per
  cent of the step over the next cycles). From the first whole cycle of the step on, after each cycle the mean
  of the first half of its cycles is compared with that of the second half: a creep back beyond the bound (t x
  sigma x sqrt(2 / half), t Student's 99.73 % quantile for the reference's cycles, sigma the reference's robust
  standard deviation of the mean-force offset) is ``fixture`` (the held trips are released with that cause and
  the new level becomes the reference); a step flat within the bound where a creep of 2 % of it would have
  exceeded the bound is ``offset_jump`` (cause ``sensor``; the offset is subtracted from the mean force and the
  residual from then on, so a later specimen change is still seen); after ``confirm_cycles`` without either,
  ``undetermined`` (the held trips are released: the safe side). A step no specimen detector tripped on is
  recorded as a load_cell event with action ``record`` and its cause (fixture or undetermined).

The reference is a rolling one: the median and robust sigma of the block's last ``reference_cycles`` normal
cycles (a sweep's gradual change of frequency is not a fault; what the load_cell judges is abrupt). A verdict of
``specimen``, ``fixture`` or ``undetermined`` makes the block learn its reference afresh.
"""
from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import t as student_t

# cause labels an Event carries (DetectorEvent.cause; its message starts with "[cause CAUSE/CODE]" for people too)
CAUSES = ('specimen', 'fixture', 'sensor', 'model', 'control', 'program', 'undetermined')
CAUSE_OF_TYPE = {'residual': 'specimen', 'stiffness_change': 'specimen', 'force_drift': 'specimen',
                 'tracking': 'control', 'cycle_count': 'program', 'elapsed_time': 'program',
                 'model_fit': 'model', 'load_cell': 'sensor'}
STUCK_FRACTION = 0.01      # force amplitude below this fraction of the expected: the load cell is stuck
SHAPE_DROP = 0.01          # shape factor down by more: the peaks are clipped (saturation)
K_TOLERANCE, C_TOLERANCE = 0.03, 0.10    # stiffness / loop (C_eq) ratio unchanged within these (at least 5 sigma)
SHAPE_RISE = 0.1           # shape factor up by more: the cycle is distorted (a spike, a part-cycle freeze)
RESIDUAL_JUMP = 2.0        # a residual over this many times the recent cycles' (+ 5 sigma) is an abrupt change
PLAIN_CHANGE = 3.0         # a trip whose stiffness is off by this many times K_TOLERANCE is the specimen at once
CREEP = 0.02               # a fixture slip's mean force creeps back by at least this fraction of the step


def _robust_sigma(values) -> float:
    v = np.asarray(values, dtype=float)
    return float(1.4826 * np.median(np.abs(v - np.median(v)))) if v.size else math.nan


def _ratio(a: float, b: float) -> float:
    return a / b if b and math.isfinite(a) and math.isfinite(b) else math.nan


def _complex_stiffness(props: dict) -> complex:
    return cmath.rect(props.get('k_dyn', math.nan), props.get('loss_angle', math.nan))


@dataclass
class ModelFit:
    """Outcome of the model-fit check: measured/model ratios (median over the reference cycles) and tolerances."""

    k_ratio: float
    c_ratio: float
    k_tolerance: float
    c_tolerance: float
    rho: complex                 # median complex-stiffness ratio K*/K*_model (Eq. 2, 26)
    cycles: int

    @property
    def fits(self) -> bool:
        return abs(self.k_ratio - 1) <= self.k_tolerance and abs(self.c_ratio - 1) <= self.c_tolerance

    def first_harmonic_residual(self, c) -> float:
        """RMS [N] of the first-harmonic force left once the model is scaled by rho: |K* - rho K*_m| x0/sqrt(2)."""
        k, km = _complex_stiffness(c.measured), _complex_stiffness(c.model)
        return abs(k - self.rho * km) * c.amplitude / math.sqrt(2)


class ModelFitCheck:
    """Gathers the program's first steady cycles and decides whether the model fits (module docstring)."""

    def __init__(self, spec):
        self.spec = spec
        self.seen = 0
        self.rows: list[tuple] = []
        self.result: ModelFit | None = None

    def observe(self, c) -> ModelFit | None:
        """The ModelFit on the cycle that completes the reference, None otherwise."""
        if self.result is not None:
            return None
        self.seen += 1
        if self.seen <= self.spec.settle_cycles:
            return None
        k = _ratio(c.measured.get('k_dyn', math.nan), c.model.get('k_dyn', math.nan))
        cq = _ratio(c.measured.get('c_eq', math.nan), c.model.get('c_eq', math.nan))
        rho = _complex_stiffness(c.measured) / _complex_stiffness(c.model) if c.model.get('k_dyn') else math.nan
        if not (math.isfinite(k) and math.isfinite(cq) and cmath.isfinite(rho)):
            return None
        self.rows.append((k, cq, rho))
        if len(self.rows) < self.spec.reference_cycles:
            return None
        ks, cs, rhos = (np.array(col) for col in zip(*self.rows, strict=True))
        n = len(ks)
        se = 1.2533 / math.sqrt(n)              # standard error of a median, per robust sigma
        self.result = ModelFit(float(np.median(ks)), float(np.median(cs)),
                               self.spec.threshold + 3 * se * _robust_sigma(ks),
                               self.spec.c_eq_threshold + 3 * se * _robust_sigma(cs),
                               complex(float(np.median(rhos.real)), float(np.median(rhos.imag))), n)
        return self.result


@dataclass
class Reference:
    """The load cell's view of a block's recent normal cycles: medians and robust sigmas of the signature."""

    k: float
    c: float
    offset: float                # measured - model mean force [N]
    shape: float
    amplitude: float             # force amplitude / model force amplitude
    residual: float              # RMS of measured - model force [N]
    sigma: dict


@dataclass
class Held:
    """Specimen-detector trips held back while the load cell judges what the cycles after them show."""

    trips: list                  # (detector spec, judged tuple, Cycle it tripped on)
    since: int                   # program cycle of the first trip or anomaly
    offsets: list = field(default_factory=list)   # mean-force offset from the reference [N], cycles of a step

    @property
    def step(self) -> float:
        """The mean-force step [N] on its first whole cycle (NaN while none is seen)."""
        return self.offsets[0] if self.offsets else math.nan


@dataclass
class Verdict:
    """What the load cell made of a cycle: release the held trips with `cause`, or report a sensor `code`."""

    cause: str                   # specimen | fixture | sensor | undetermined
    code: str                    # stuck | saturation | spikes | offset_jump | mean_step | changed
    trips: list = field(default_factory=list)
    value: float = math.nan
    reference: float = math.nan
    threshold: float = math.nan
    units: str = ''
    detail: str = ''


class LoadCellJudge:
    """Tells load-cell faults from specimen changes by their cycle signature (module docstring)."""

    def __init__(self, spec):
        self.spec = spec
        self.learning: dict[int, tuple[list, list]] = {}   # block -> ([steady cycles seen], signature rows)
        self.references: dict[int, Reference] = {}
        self.reference: Reference | None = None           # of the block of the cycle being judged
        self.held: Held | None = None
        self.offset = 0.0            # a load-cell offset found (subtracted from later cycles) [N]
        self.fault = ''              # stuck | saturation while the load cell is out (the detectors are blind)
        self.last = 'normal'         # the previous cycle's class: a clipped cycle counts when two are in a row
        self.reported: set = set()   # (block, code) reported: each code once per block, like a detector's trip
        self.settling = 0            # steady cycles after a resume judged only for a stuck cell (see rearm)

    @staticmethod
    def _signature(c) -> tuple:
        m, md = c.measured, c.model
        k = _ratio(m.get('k_dyn', math.nan), md.get('k_dyn', math.nan))
        cq = _ratio(m.get('c_eq', math.nan), md.get('c_eq', math.nan))
        offset = m.get('force_mean', math.nan) - md.get('force_mean', math.nan)
        shape = _ratio(m.get('force_amplitude', math.nan), m.get('k_dyn', math.nan) * c.amplitude)
        amp = _ratio(m.get('force_amplitude', math.nan), md.get('force_amplitude', math.nan))
        return k, cq, offset, shape, amp, c.residual_rms

    def compensate(self, c):
        """Cycle c with a found load-cell offset taken out of its mean force and residual (mean + zero-mean
        parts of the residual: rms^2 = var + mean^2).
        """
        if not self.offset:
            return c
        m = dict(c.measured)
        mean_residual = m.get('force_mean', math.nan) - c.model.get('force_mean', math.nan)
        m['force_mean'] = m.get('force_mean', math.nan) - self.offset
        rms2 = c.residual_rms ** 2 - mean_residual ** 2 + (mean_residual - self.offset) ** 2
        return replace(c, measured=m, residual_rms=math.sqrt(max(rms2, 0.0)))

    def _learn(self, block: int, sig) -> None:
        seen, rows = self.learning.setdefault(block, ([], []))
        seen.append(1)
        if len(seen) <= self.spec.settle_cycles or not all(math.isfinite(s) for s in sig):
            return
        rows.append(sig)
        if len(rows) < self.spec.reference_cycles:
            return
        del rows[:-self.spec.reference_cycles]      # a rolling window: a sweep's slow change is not a fault
        cols = [np.array(col) for col in zip(*rows, strict=True)]
        med = [float(np.median(col)) for col in cols]
        names = ('k', 'c', 'offset', 'shape', 'amplitude', 'residual')
        sig_ = {name: _robust_sigma(col) for name, col in zip(names, cols, strict=True)}
        self.references[block] = Reference(*med, sigma=sig_)

    def expected_amplitude(self, c) -> float:
        return self.reference.amplitude * c.model.get('force_amplitude', math.nan)

    def classify(self, c) -> tuple[str, tuple]:
        """(stuck | saturated | distorted | changed | step | normal, signature) of cycle c against the reference."""
        ref, s = self.reference, self._signature(c)
        k, cq, offset, shape, amp, residual = s
        if not amp >= STUCK_FRACTION * ref.amplitude:
            return 'stuck', s
        if shape < ref.shape - max(SHAPE_DROP * ref.shape, 5 * ref.sigma['shape']):
            return 'saturated', s
        if shape > ref.shape + max(SHAPE_RISE * ref.shape, 5 * ref.sigma['shape']):
            return 'distorted', s        # a spike, or a reading that froze part of the way through the cycle
        if self.changed(s):
            return 'changed', s
        if abs(offset - ref.offset) > self.step_bound(c):
            return 'step', s
        if residual > RESIDUAL_JUMP * ref.residual + 5 * ref.sigma['residual']:
            return 'distorted', s        # the model's misfit jumped from one cycle to the next: not gradual
        return 'normal', s

    def changed(self, s, factor: float = 1.0) -> bool:
        ref = self.reference
        return (abs(s[0] / ref.k - 1) > factor * max(K_TOLERANCE, 5 * ref.sigma['k'] / ref.k)
                or abs(s[1] / ref.c - 1) > factor * max(C_TOLERANCE, 5 * ref.sigma['c'] / ref.c))

    def step_bound(self, c) -> float:
        return max(self.spec.threshold * self.expected_amplitude(c), 5 * self.reference.sigma['offset'], 1e-9)

    def observe(self, c, trips: list) -> list[Verdict]:
        """Judge cycle c (already compensated) with the specimen-detector trips on it; the verdicts reached."""
        self.reference = self.references.get(c.block)
        if self.reference is None:      # a new block: what was held is released on the safe side
            out = self._release('undetermined', 'mean_step', c, None, 'the block ended before the load cell could '
                                'tell') if self.held and self.held.trips else []
            self.held = None
            self._learn(c.block, self._signature(c))
            return out + ([Verdict('specimen', 'changed', trips)] if trips else [])
        kind, s = self.classify(c)
        if self.settling and kind != 'stuck':
            self.settling -= 1
            return [Verdict('specimen', 'changed', trips)] if trips else []
        # the cycle a step happens in loses its shape too (its loop does not close): clipping is two in a row
        last, self.last = self.last, kind
        if kind == 'stuck' or (kind == 'saturated' and last == 'saturated'):
            return self._sensor(c, 'stuck' if kind == 'stuck' else 'saturation', s)
        if self.held is None:
            if kind == 'normal' and not trips:
                self._learn(c.block, s)
                return []
            if trips and kind == 'changed' and self.changed(s, PLAIN_CHANGE):
                return [Verdict('specimen', 'changed', trips)]
            if trips and kind == 'normal':
                # nothing abrupt in the force: a detector whose reference is older saw a gradual change (fatigue)
                self._learn(c.block, s)
                return [Verdict('specimen', 'changed', trips, detail='a gradual change: the cycle is like the ones '
                                'before it')]
            # the cycle of a step holds only part of it: the step is measured from the next cycle on
            self.held = Held(list(trips), c.program_cycle)
            return []
        self.held.trips += trips
        if kind == 'saturated':
            return []
        if kind == 'changed':
            self._relearn(c.block)                  # the specimen changed: its new state is learnt afresh
            return self._release('specimen', 'changed', c, s)
        if kind == 'step' or self.held.offsets:
            return self._step(c, s)
        if not self.held.trips:                     # a transient no detector tripped on: nothing to put down
            self.held = None
            return []
        return self._sensor(c, 'spikes', s)           # normal again: a transient with no lasting change

    def _step(self, c, s) -> list[Verdict]:
        """A step of the mean force on cycle c: after each cycle, the first and second half of the cycles since
        the step are compared (a fixture slip creeps back, a load-cell offset stays), until one is told or
        ``confirm_cycles`` have gone by.
        """
        held = self.held
        held.offsets.append(s[2] - self.reference.offset)
        k = len(held.offsets)
        if k < 2:
            return []
        half = k // 2
        early, late = float(np.mean(held.offsets[:half])), float(np.mean(held.offsets[-half:]))
        # 3 sigma, widened for a sigma estimated from few reference cycles (Student's t, 99.73 % two-sided)
        n = max(self.spec.reference_cycles, 2)
        noise = float(student_t.ppf(0.99865, n - 1)) * max(self.reference.sigma['offset'], 1e-9) * math.sqrt(2 / half)
        creep = (early - late) * math.copysign(1.0, held.step)       # back towards the level before the step
        detail = (f'mean force stepped by {held.step:+.6g} N with K_dyn and C_eq unchanged; over {k} cycles it '
                  f'moved back {creep:+.6g} N (bound {noise:.3g} N)')
        if creep > noise:
            self._relearn(c.block)
            return self._release('fixture', 'mean_step', c, s, detail + ': it relaxes, a displacement step '
                                 '(fixture slip)')
        if abs(creep) <= noise and CREEP * abs(held.step) > noise:
            self.offset += late
            return self._sensor(c, 'offset_jump', s, detail + ': flat, a load-cell offset (subtracted from here '
                                'on)', value=held.step)
        if k < max(self.spec.confirm_cycles, 2):
            return []
        self._relearn(c.block)
        return self._release('undetermined', 'mean_step', c, s, detail + ': too little to tell a load-cell offset '
                             'from a fixture slip')

    def _relearn(self, block: int) -> None:
        """A change of the specimen or its fixture is its new state: the block's signature is learnt afresh."""
        self.references.pop(block, None)
        self.learning.pop(block, None)

    def _release(self, cause, code, c, s, detail='') -> list[Verdict]:
        """Release the held trips with `cause`; a mean-force step no detector tripped on is a verdict of its own
        (the Monitor records it as a load_cell event: a step nobody explained is not passed over in silence).
        """
        held, self.held = self.held, None
        trips = held.trips if held else []
        step = held.step if held else math.nan
        bound = self.step_bound(c) if self.reference is not None else math.nan
        return [Verdict(cause, code, trips, step, 0.0, bound, 'N', detail)]

    def _sensor(self, c, code, s, detail='', value=math.nan) -> list[Verdict]:
        ref = self.reference
        self.held = None
        if (c.block, code) in self.reported:
            return []
        self.reported.add((c.block, code))
        if code in ('stuck', 'saturation'):
            self.fault = code
        if code == 'stuck':
            reference = self.expected_amplitude(c)
            value, threshold, units = c.measured.get('force_amplitude', math.nan), STUCK_FRACTION * reference, 'N'
            detail = detail or 'the force amplitude fell to nothing while the displacement kept its amplitude'
        elif code == 'saturation':
            value, reference, threshold, units = s[3], ref.shape, SHAPE_DROP, '-'
            detail = detail or ('the force peaks are cut (half peak-to-peak / first harmonic fell from '
                                f'{ref.shape:.4f} to {s[3]:.4f}): the load cell is at its range')
        elif code == 'spikes':
            value, reference, threshold, units = c.residual_rms, math.nan, math.nan, 'N'
            detail = detail or 'a cycle off and the next one back as before: a transient in the force signal'
        else:
            reference, threshold, units = 0.0, self.step_bound(c), 'N'
        return [Verdict('sensor', code, [], value, reference, threshold, units, detail)]

    def rearm(self) -> None:
        """After a hold: judge afresh; a rested specimen relaxes, so settle_cycles + 2 cycles judge only stuck."""
        self.fault, self.held, self.last = '', None, 'normal'
        self.settling = self.spec.settle_cycles + 2
        self.reported.clear()
