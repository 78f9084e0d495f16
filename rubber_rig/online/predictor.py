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

"""ROS-free glue behind the element_model node: run a core element model on streamed sample batches.

Why a history buffer: a rebuilt model (new parameters, or a new temperature when the model follows the rig's
temperature channel) starts from rest, but the specimen does not. Running the new model over the last few
seconds of measured displacement (``warmup_time``) before it predicts again removes the start-up transient
of the fractional (long-memory) branch and the friction reference state; a batch run over 5 s at 5 kHz costs
a few milliseconds.

Why a friction reversal deadband (``friction_reversal_threshold``): the model is driven by the *measured*
displacement, and with the paper's rule every sensor-noise wiggle is a velocity reversal that resets Berg's
reference state, which collapses the friction loop (C_eq several per cent low at 0.5 Hz / 0.5 mm with 0.2 um
noise). About 10x the displacement noise RMS keeps the noise out of the reference state (see
rubber_rig.models.friction); 0 is the paper's rule.

Why non-finite samples are skipped: one NaN displacement fed to the model would poison its state (the
fractional branch remembers its whole history), and every later prediction would be NaN. A sample whose
displacement is not finite is left out of the model run - exactly as if its frame had been lost - and its
prediction is NaN; the model continues from the last finite sample, so the predictions afterwards equal those of
a run without the bad samples. A batch whose sequence goes backwards (a restarted driver) starts the model
afresh; batches the node cannot use at all (mismatched array lengths, a sample period that is not a finite
positive number) are refused before they get here (``batch_problem``).

Model files: ``parameter_set`` may also name a model file (a .yaml with an ``elements`` list, see
rubber_rig.models.modelfile): the predictor then runs that composite model (:class:`ModelFileParams`; the
friction reversal deadband applies to its Berg elements unless an element sets its own ``reversal_threshold``)
and its branches are the model's own (``branch_names``, e.g. elastic_1, viscous, friction, elastic_2). A parameter
set of another model type (Kelvin-Voigt, tangent spring + Maxwell + Berg) runs the same way, as the model file it
describes. Every choice is built through its ModelSpec (rubber_rig.models.catalogue), as the simulated rig builds
its specimen; the temperature sources stay seed 000 (fractional Zener + Berg), the only temperature table.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rubber_rig.models import (
    ZenerBergParams,
    build_model,
    canonical_model,
    load_parameter_set,
    parameter_set_info,
    parameters_at_temperature,
)
from rubber_rig.models.modelfile import ModelSpec, is_model_file, load_model_file, spec_from_params
from rubber_rig.models.params import ParameterValueError

SOURCES = ('parameter_set', 'temperature', 'rig_temperature', 'values')
CHOICE_FIELDS = ('source', 'parameter_set', 'temperature', 'friction_reversal_threshold')   # and 'values.<name>'
# [m] 10x the simulated rig's default displacement noise (rig.config.SimOptions.displacement_noise = 0.2 um);
# 5x is too little for quasi-static motion (see rubber_rig.models.friction)
DEFAULT_REVERSAL_THRESHOLD = 2e-6


class ChoiceError(ValueError):
    """An invalid :class:`ModelChoice`; ``field`` names the field (and so the element_model parameter) at fault."""

    def __init__(self, field: str, why: str):
        super().__init__(why)
        self.field = field


@dataclass(frozen=True, eq=False)
class ModelFileParams:
    """The model a model file describes (``parameter_set: FILE.yaml`` with an ``elements`` list): what the
    predictor runs in place of :class:`ZenerBergParams`. ``as_dict()`` {parameter name: SI value}, names as
    :meth:`ModelSpec.parameters` gives them (bare, or ``label.param`` where a name repeats; an
    operating_point_spring's coefficient tables are not among them).
    """

    path: str                 # as given in parameter_set
    spec: ModelSpec
    what: str = 'model file'  # or 'parameter set' (of a model type other than fractional_zener_berg)

    @property
    def model_name(self) -> str:
        """The element types in parallel, e.g. 'fractional_zener + berg + polynomial_spring'."""
        return ' + '.join(e.type for e in self.spec.elements)

    @property
    def temperature(self) -> float:
        """[degC] the file says its values are valid at (its ``temperature``), NaN when it says none."""
        t = self.spec.meta.get('temperature')
        return math.nan if t is None else float(t)

    def as_dict(self) -> dict:
        return {k: float(v) for k, v in self.spec.values().items()}

    def __str__(self) -> str:
        values = ', '.join(f'{k}={v:.6g}' for k, v in self.as_dict().items())
        return f'{self.what} {self.path} ({self.spec.name}: {self.model_name}; {values})'


def load_model_choice_file(path: str) -> ModelFileParams:
    """A model file as :class:`ModelFileParams`; raises :class:`ChoiceError` ('parameter_set') naming the file
    and the problem (missing, not YAML, unknown element type or parameter, missing value, bad unit, bad value).
    """
    full = str(Path(path).expanduser())
    if not Path(full).is_file():
        raise ChoiceError('parameter_set', f'parameter set {path!r}: no such file'
                          + (f' ({full})' if full != str(path) else ''))
    try:
        spec = load_model_file(path)
    except (OSError, ValueError, TypeError, KeyError, AttributeError) as exc:
        raise ChoiceError('parameter_set', f'model file {path!r}: {_why(exc, path)}') from None
    return ModelFileParams(str(path), spec)


def _why(exc: Exception, path: str) -> str:
    """The message of a file's error without the file name it often starts with (the caller names the file)."""
    why = str(exc).strip('"\'') if isinstance(exc, KeyError) else str(exc)
    for prefix in (str(Path(str(path).split(':')[0]).expanduser()) + ': ', str(path) + ': '):
        if why.startswith(prefix):
            return why[len(prefix):]
    return why


def _names_model_file(name: str) -> bool:
    """True when ``name`` is meant as a model file: a .yaml/.yml file with an ``elements`` list, or a .yaml/.yml
    path that does not exist and has no ``:SET`` (a parameter table would need the file as well).
    """
    if is_model_file(name):
        return True
    return str(name).endswith(('.yaml', '.yml')) and not Path(str(name)).expanduser().exists()


@dataclass(frozen=True)
class ModelChoice:
    """Which parameters the model runs with (what the element_model node's parameters select)."""

    source: str = 'parameter_set'                 # one of SOURCES
    parameter_set: str = 'swing_arm_joint_20C'     # a shipped set, FILE.yaml[:SET] (parameter table) or a model file
    temperature: float = 20.0                     # [degC] for source 'temperature' (start value for 'rig_temperature')
    values: dict = field(default_factory=dict)    # k0, k_inf, tau, alpha, x2, f_fmax [SI] for source 'values'
    model: str = 'fractional_zener_berg'
    friction_reversal_threshold: float = DEFAULT_REVERSAL_THRESHOLD   # [m] Berg reversal deadband, 0 = paper's rule

    def resolve(self, temperature: float | None = None) -> tuple[ZenerBergParams | ModelFileParams, str, float]:
        """(validated parameters, parameter-set name or '', temperature [degC] or NaN); the parameters are a
        :class:`ModelFileParams` when ``parameter_set`` is a model file or a set of another model type.

        Raises :class:`ChoiceError` whose ``field`` is the field of this choice that is wrong
        ('values.alpha', 'parameter_set', 'temperature', 'source', 'friction_reversal_threshold').
        """
        if canonical_model(self.model) != 'fractional_zener_berg':
            raise ChoiceError('model', f"model {self.model!r} is not available online "
                              "(only 'fractional_zener_berg')")
        d = self.friction_reversal_threshold
        if not (isinstance(d, (int, float)) and math.isfinite(d) and d >= 0.0):
            raise ChoiceError('friction_reversal_threshold', 'parameter friction_reversal_threshold must be a '
                              f'finite displacement >= 0 [m], got {d!r}')
        if self.source == 'parameter_set':
            if _names_model_file(self.parameter_set):
                p = load_model_choice_file(self.parameter_set)
                return p, self.parameter_set, p.temperature
            try:   # a file set may be missing, unreadable, not YAML or hold bad values: all are a ValueError here
                p = load_parameter_set(self.parameter_set)
            except (OSError, ValueError, TypeError, KeyError, AttributeError) as exc:
                raise ChoiceError('parameter_set', f'parameter set {self.parameter_set!r}: '
                                  f'{_why(exc, self.parameter_set)}') from None
            info = parameter_set_info(self.parameter_set)
            if not isinstance(p, ZenerBergParams):   # runs as the model file it describes
                spec = spec_from_params(p, info['name'])
                spec.meta['temperature'] = info['temperature']
                p = ModelFileParams(self.parameter_set, spec, 'parameter set')
            return p, self.parameter_set, info['temperature']
        if self.source in ('temperature', 'rig_temperature'):
            t = self.temperature if temperature is None else float(temperature)
            try:
                return parameters_at_temperature(t), '', t
            except ValueError as exc:
                raise ChoiceError('temperature', str(exc)) from None
        if self.source == 'values':
            try:
                return ZenerBergParams.from_dict(dict(self.values)), '', math.nan
            except ParameterValueError as exc:
                raise ChoiceError('values.' + exc.parameter, str(exc)) from None
        raise ChoiceError('source', f'source {self.source!r} is not one of {", ".join(SOURCES)}')

    def checked(self, changed) -> tuple:
        """:meth:`resolve` after checking every field among ``changed`` (element_model parameter names: 'source',
        'values.k0', ...), used by the current source or not: a later switch of ``source`` must never meet an invalid
        value. Every failure is a ChoiceError naming a parameter; one that is not (a bug in a reader) names the
        parameters that changed, with the exception's type.
        """
        try:
            if self.source not in SOURCES:
                raise ChoiceError('source', f"source '{self.source}' is not one of {', '.join(SOURCES)}")
            if any(name.startswith('values.') for name in changed):
                ModelChoice(source='values', values=self.values).resolve()
            if 'parameter_set' in changed and self.source != 'parameter_set':
                ModelChoice(source='parameter_set', parameter_set=self.parameter_set).resolve()
            if 'temperature' in changed:
                ModelChoice(source='temperature', temperature=self.temperature).resolve()
            return self.resolve()
        except ChoiceError:
            raise
        except Exception as exc:   # noqa: BLE001 - whatever goes wrong, refuse the choice with a reason
            names = ', '.join(sorted(n for n in changed if n in CHOICE_FIELDS or n.startswith('values.')))
            raise ChoiceError(names or 'parameter_set', f'{type(exc).__name__}: {exc}') from None


class OnlinePredictor:
    """Predicts the force of each incoming batch; rebuilds the model when the choice or the temperature changes."""

    def __init__(self, choice: ModelChoice, warmup_time: float = 5.0, temperature_hysteresis: float = 0.5,
                 resolved: tuple | None = None):
        """``resolved``: what ``choice.resolve()`` returned when the caller validated the choice (a parameter
        file is then read once); resolved here otherwise.
        """
        self.choice = choice
        self.warmup_time = warmup_time
        self.temperature_hysteresis = temperature_hysteresis
        self.params, self.parameter_set, self.temperature = resolved if resolved is not None else choice.resolve()
        self.model = None
        self.dt = None
        self.next_sequence = None
        self._history: deque[np.ndarray] = deque()
        self._history_len = 0
        self._dirty = True

        self.nonfinite_samples = 0      # samples whose displacement was not finite (skipped by the model)
        self.restarts = 0               # times the sequence went backwards and the model started afresh

    def set_choice(self, choice: ModelChoice, resolved: tuple | None = None) -> None:
        """Switch to ``choice``; the model is rebuilt and warmed up on the next batch. ``resolved``: what
        ``choice.resolve()`` returned when the choice was validated (so a parameter file is read once, in the
        validating callback); otherwise it is resolved here (raises ValueError, nothing changes then).
        """
        if resolved is None:
            resolved = choice.resolve()
        self.choice = choice
        self.params, self.parameter_set, self.temperature = resolved
        self._dirty = True

    def goes_back(self, first_sequence: int) -> bool:
        """True if a batch starting at ``first_sequence`` does not follow the last one (sequence backwards or
        repeated: a restarted driver, or a replayed recording).
        """
        return self.next_sequence is not None and first_sequence < self.next_sequence

    def restart(self) -> None:
        """Forget the stream: the next batch builds the model from rest (no warm-up on the old history)."""
        self.model, self.dt, self.next_sequence = None, None, None
        self._history.clear()
        self._history_len = 0
        self._dirty = True
        self.restarts += 1

    @property
    def branch_names(self) -> list[str]:
        return list(self.model.branch_names) if self.model is not None else []

    @property
    def model_name(self) -> str:
        """'fractional_zener_berg', or a model file's element types ('fractional_zener + berg + ...')."""
        return self.params.model_name if isinstance(self.params, ModelFileParams) else 'fractional_zener_berg'

    def process(self, first_sequence: int, dt: float, x: np.ndarray,
                temperature: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Predicted force and branch forces [n_branch, n] for one batch of measured displacement.

        Samples whose displacement is not finite are skipped by the model and predicted as NaN (module doc); a
        batch whose sequence goes backwards restarts the model (``restart``).
        """
        if self.goes_back(first_sequence):
            self.restart()
        x = np.asarray(x, dtype=np.float64)
        self.next_sequence = first_sequence + len(x)
        if self.choice.source == 'rig_temperature' and temperature is not None and math.isfinite(temperature):
            moved = abs(temperature - self.temperature) >= self.temperature_hysteresis
            if not math.isfinite(self.temperature) or moved:
                try:
                    self.params, self.parameter_set, self.temperature = self.choice.resolve(temperature)
                    self._dirty = True
                except ValueError:
                    pass  # outside the identified range: keep the last valid parameters
        if self._dirty or self.dt is None or not math.isclose(dt, self.dt, rel_tol=1e-9):
            self._rebuild(dt)
        good = np.isfinite(x)
        bad = x.size - int(np.count_nonzero(good))
        self.nonfinite_samples += bad
        xs = x[good] if bad else x
        if xs.size:
            t, b = self.model.run(xs, return_branches=True)
            if not np.all(np.isfinite(t)):
                # finite input, non-finite output: never carry such a state on; start afresh on the next batch
                unpredicted = self._unpredicted(x.size)
                self.restart()
                self.next_sequence = first_sequence + len(x)
                return unpredicted
            if bad:
                total, branches = self._unpredicted(x.size)
                total[good], branches[:, good] = t, b
            else:
                total, branches = np.asarray(t), np.asarray(b)
        else:
            total, branches = self._unpredicted(x.size)
        self._remember(xs)
        return total, branches

    def _unpredicted(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """NaN force and branch forces for `n` samples (the ones the model skipped fill in)."""
        return np.full(n, np.nan), np.full((len(self.model.branch_names), n), np.nan)

    # -- internals --------------------------------------------------------------------------------------
    def _rebuild(self, dt: float) -> None:
        spec = self.params.spec if isinstance(self.params, ModelFileParams) else spec_from_params(self.params)
        self.model = build_model(spec, dt, friction_reversal_threshold=self.choice.friction_reversal_threshold)
        if self.dt is not None and math.isclose(dt, self.dt, rel_tol=1e-9) and self._history:
            self.model.run(np.concatenate(list(self._history)), return_branches=False)  # warm up (see module doc)
        else:
            self._history.clear()
            self._history_len = 0
        self.dt = dt
        self._dirty = False

    def _remember(self, x: np.ndarray) -> None:
        keep = int(self.warmup_time / self.dt) if self.dt else 0
        if keep <= 0 or len(x) == 0:
            return
        self._history.append(np.array(x, dtype=np.float64))
        self._history_len += len(x)
        while self._history and self._history_len - len(self._history[0]) >= keep:
            self._history_len -= len(self._history.popleft())


def batch_problem(first_sequence: int, sample_period: float, n_displacement: int, n_force: int) -> str | None:
    """Why a sample batch cannot be used at all (None if it can): the node drops such a batch with a warning."""
    if n_force != n_displacement:
        return f'{n_displacement} displacement and {n_force} force samples (lengths differ)'
    if not (isinstance(sample_period, (int, float)) and math.isfinite(sample_period) and sample_period > 0):
        return f'sample_period {sample_period!r} s is not a finite positive number'
    if first_sequence < 0:
        return f'first_sequence {first_sequence} is negative'
    return None


class BlockIndex:
    """Maps sample sequences to the program block they belong to, from the streamed setpoint batches."""

    def __init__(self, keep: int = 4096):
        self._ranges: deque[tuple[int, int, int]] = deque(maxlen=keep)
        self.ended = False             # the latest batch ended its stream: later samples belong to no block

    def add(self, first_sequence: int, n: int, block_index: int) -> None:
        if self._ranges and first_sequence < self._ranges[-1][0]:
            self._ranges.clear()       # the setpoint sequence went backwards: a new run, the old ranges are void
        self._ranges.append((first_sequence, first_sequence + n, block_index))

    def covered(self, sequence: int) -> bool:
        """True once setpoints up to ``sequence`` have been seen (a -1 block from segments is then final)."""
        return bool(self._ranges) and sequence < self._ranges[-1][1]

    def segments(self, first_sequence: int, n: int) -> list[tuple[int, int, int]]:
        """Split the samples [first_sequence, first_sequence + n) by block: [(start, stop, block)], offsets
        into the batch, stop exclusive; samples no setpoint batch covers get block -1.
        """
        end = first_sequence + n
        marks = []                                   # (first, end, block) of ranges overlapping the samples
        for r in reversed(self._ranges):
            if r[1] <= first_sequence:
                break
            if r[0] < end:
                marks.append(r)
        out, at = [], first_sequence
        for r_first, r_end, block in reversed(marks):
            if r_first > at:
                out.append((at, r_first, -1))
            lo, hi = max(r_first, at), min(r_end, end)
            if hi > lo:
                out.append((lo, hi, block))
                at = hi
        if at < end:
            out.append((at, end, -1))
        merged = []                                  # consecutive ranges of one block: one segment
        for seg in out:
            if merged and merged[-1][2] == seg[2] and merged[-1][1] == seg[0]:
                merged[-1] = (merged[-1][0], seg[1], seg[2])
            else:
                merged.append(seg)
        return [(lo - first_sequence, hi - first_sequence, block) for lo, hi, block in merged]
