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

"""The online predictor (ROS-free) with a model file in ``parameter_set``: it resolves, runs exactly the model
build_model makes of the file (same force to round-off, its own branches), and a file it cannot use is refused
as a ChoiceError on 'parameter_set' that names the file and the problem."""
import math

import numpy as np
import pytest

from rubber_rig.models import build_model, load_parameter_set, parameter_set_info
from rubber_rig.online.predictor import (
    DEFAULT_REVERSAL_THRESHOLD,
    ChoiceError,
    ModelChoice,
    ModelFileParams,
    OnlinePredictor,
)

MODEL = """name: bushing_20C
temperature: 20 degC
elements:
  - {type: fractional_zener, k0: 12.29 kN/mm, k_inf: 14.01 kN/mm, tau: 0.043 s, alpha: 0.659}
  - {type: berg, x2: 1.41 mm, f_fmax: 4.57 kN}
  - {type: polynomial_spring, k3: 6e11 N/m^3}
"""
# what `rubber-rig fit` writes: SI numbers with sigma / interval_95 beside the values (readers ignore them)
FITTED = """elements:
  - type: fractional_zener
    k0: 12290000.0
    k_inf: 14010000.0
    tau: 0.043
    alpha: 0.659
    sigma: {k0: 1.0e4, k_inf: 1.0e4, tau: 0.001, alpha: 0.002}
    interval_95: {k0: [12270000.0, 12310000.0]}
  - {type: berg, x2: 0.00141, f_fmax: 4570.0, sigma: {x2: 1.0e-5, f_fmax: 10.0}}
  - {type: polynomial_spring, k3: 6.0e11}
"""
DT = 1e-3


def displacement(n=6000, seed=3):
    """Two sines (1 and 3.7 Hz, 1 mm and 0.3 mm) with 0.2 um noise: reversals of several sizes for Berg."""
    t = np.arange(n) * DT
    rng = np.random.default_rng(seed)
    return 1e-3 * np.sin(2 * np.pi * t) + 0.3e-3 * np.sin(2 * np.pi * 3.7 * t + 0.4) + rng.normal(0, 0.2e-6, n)


def run_batches(p, x, size=50, first=0):
    out = [p.process(first + i, DT, x[i:i + size]) for i in range(0, x.size, size)]
    return np.concatenate([o[0] for o in out]), np.concatenate([o[1] for o in out], axis=1)


@pytest.fixture
def model_file(tmp_path):
    path = tmp_path / 'bushing.yaml'
    path.write_text(MODEL)
    return path


@pytest.mark.parametrize('text', [MODEL, FITTED], ids=['units', 'fit_output'])
def test_a_model_file_resolves_to_its_values(tmp_path, text):
    path = tmp_path / 'm.yaml'
    path.write_text(text)
    params, name, temperature = ModelChoice(parameter_set=str(path)).resolve()
    assert isinstance(params, ModelFileParams) and name == str(path)
    assert params.as_dict() == pytest.approx({'k0': 12.29e6, 'k_inf': 14.01e6, 'tau': 0.043, 'alpha': 0.659,
                                              'x2': 1.41e-3, 'f_fmax': 4570.0, 'k3': 6e11}, rel=1e-12)
    assert params.model_name == 'fractional_zener + berg + polynomial_spring'
    assert (temperature == 20.0) if text == MODEL else math.isnan(temperature)
    assert str(path) in str(params) and 'k3=6e+11' in str(params)
    # a shipped set and a parameter table (FILE.yaml, FILE.yaml:SET) are what they were
    assert ModelChoice().resolve()[0] == load_parameter_set('swing_arm_joint_20C')
    table = tmp_path / 'table.yaml'
    table.write_text('sets:\n  fit_0C: {model: fractional_zener_berg, temperature: 0.0, values: {k0: 12.31e6, '
                     'k_inf: 14.08e6, tau: 0.031, alpha: 0.796, x2: 1.58e-3, f_fmax: 7770.0}}\n')
    for name in (str(table), f'{table}:fit_0C'):
        assert ModelChoice(parameter_set=name).resolve() == (load_parameter_set('swing_arm_joint_0C'), name, 0.0)


def test_the_predictor_runs_the_model_file_as_build_model_does(model_file):
    x = displacement()
    p = OnlinePredictor(ModelChoice(parameter_set=str(model_file)))
    total, branches = run_batches(p, x)
    ref = build_model(str(model_file), DT, friction_reversal_threshold=DEFAULT_REVERSAL_THRESHOLD)
    ref_total, ref_branches = ref.run(x, return_branches=True)
    assert p.branch_names == list(ref.branch_names) == ['elastic_1', 'viscous', 'friction', 'elastic_2']
    assert p.model_name == 'fractional_zener + berg + polynomial_spring'
    assert np.max(np.abs(total)) > 5e3
    np.testing.assert_allclose(total, ref_total, rtol=1e-12, atol=1e-8)
    np.testing.assert_allclose(branches, ref_branches, rtol=1e-12, atol=1e-8)
    np.testing.assert_allclose(branches.sum(axis=0), total, rtol=1e-12, atol=1e-8)
    # the deadband reaches the file's Berg element; the cubic spring adds k3 x^3 exactly
    assert p.model.elements[1].reversal_threshold == DEFAULT_REVERSAL_THRESHOLD
    np.testing.assert_allclose(branches[3], 6e11 * x ** 3, rtol=1e-12, atol=1e-12)


def test_switching_to_a_model_file_warms_it_up_on_the_history(model_file):
    """After set_choice the model is rebuilt and run over the remembered displacement (warmup_time, whole
    batches) before it predicts: with a history longer than the record the new model's predictions equal a run
    of the file's model over the whole record."""
    x = displacement()
    p = OnlinePredictor(ModelChoice(), warmup_time=60.0)
    half = 3000
    run_batches(p, x[:half])
    choice = ModelChoice(parameter_set=str(model_file))
    p.set_choice(choice, choice.resolve())
    total, _ = run_batches(p, x[half:], first=half)
    ref = build_model(str(model_file), DT, friction_reversal_threshold=DEFAULT_REVERSAL_THRESHOLD).run(x)
    np.testing.assert_allclose(total, ref[half:], rtol=1e-12, atol=1e-8)
    assert p.branch_names == ['elastic_1', 'viscous', 'friction', 'elastic_2']
    # and back to the shipped set: three branches again
    p.set_choice(ModelChoice())
    run_batches(p, x[:100], first=x.size)
    assert p.branch_names == ['elastic', 'viscous', 'friction'] and p.model_name == 'fractional_zener_berg'


def test_non_finite_samples_are_skipped_by_a_model_file_model(model_file):
    x = displacement(2000)
    bad = x.copy()
    bad[[10, 500, 501, 1999]] = np.nan
    p = OnlinePredictor(ModelChoice(parameter_set=str(model_file)))
    total, _ = run_batches(p, bad)
    ref = build_model(str(model_file), DT, friction_reversal_threshold=DEFAULT_REVERSAL_THRESHOLD)
    good = np.isfinite(bad)
    assert np.all(np.isnan(total[~good]))
    np.testing.assert_allclose(total[good], ref.run(bad[good]), rtol=1e-12, atol=1e-8)


@pytest.mark.parametrize('text, problem', [
    ('elements:\n  - {type: fractional_zenner, k0: 1 kN/mm}\n', "unknown element type 'fractional_zenner'"),
    ('elements:\n  - {type: berg, x2: 1.41 mm}\n', 'berg needs f_fmax'),
    ('elements:\n  - {type: berg, x2: 1.41 kN, f_fmax: 4.57 kN}\n', 'elements[0].x2'),
    ('elements:\n  - {type: berg, x2: 1.41 furlong, f_fmax: 4.57 kN}\n', 'elements[0].x2'),
    ('elements:\n  - {type: berg, x2: 1.41 mm, f_fmax: 4.57 kN, k9: 1}\n', "unknown parameter 'k9'"),
    ('elements:\n  - {type: fractional_zener, k0: 14 kN/mm, k_inf: 12 kN/mm, tau: 0.04 s, alpha: 0.6}\n',
     'k_inf'),
    ('elements: []\n', 'needs "elements"'),
    ('elements: [{type: berg\n', 'not valid YAML'),
], ids=['unknown_type', 'missing_value', 'wrong_dimension', 'unknown_unit', 'unknown_parameter', 'k_inf_below_k0',
        'no_elements', 'not_yaml'])
def test_a_bad_model_file_is_a_parameter_set_error_naming_file_and_problem(tmp_path, text, problem):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(ChoiceError) as err:
        ModelChoice(parameter_set=str(path)).resolve()
    assert err.value.field == 'parameter_set'
    assert str(path) in str(err.value) and problem in str(err.value), str(err.value)
    assert str(err.value).count(str(path)) == 1, str(err.value)       # the path once, not twice


def test_a_missing_model_file_is_a_parameter_set_error(tmp_path, model_file):
    missing = tmp_path / 'nope.yaml'
    with pytest.raises(ChoiceError) as err:
        ModelChoice(parameter_set=str(missing)).resolve()
    assert err.value.field == 'parameter_set' and str(missing) in str(err.value) and 'no such file' in str(err.value)
    # a predictor refuses the switch and keeps running what it ran
    p = OnlinePredictor(ModelChoice(parameter_set=str(model_file)))
    before = p.params
    with pytest.raises(ChoiceError):
        p.set_choice(ModelChoice(parameter_set=str(missing)))
    assert p.params is before and p.choice.parameter_set == str(model_file)


@pytest.mark.parametrize('choice', [ModelChoice(), ModelChoice(source='temperature', temperature=-13.0),
                                    ModelChoice(source='values', values=load_parameter_set('swing_arm_joint_0C')
                                                .as_dict())], ids=['parameter_set', 'temperature', 'values'])
def test_the_seed_000_sources_give_the_forces_of_its_elements(choice):
    """The seed-000 sources are built through their ModelSpec like a model file; the forces must stay those of
    fractional Zener + Berg built element by element (1e-9 relative), with the friction deadband.
    """
    from rubber_rig.models import ParallelModel
    from rubber_rig.models.catalogue import fractional_element
    from rubber_rig.models.friction import BergFriction
    x = displacement()
    p = OnlinePredictor(choice)
    total, branches = run_batches(p, x)
    q = p.params
    direct = ParallelModel([fractional_element(q.k0, q.k_inf, q.tau, q.alpha, DT),
                            BergFriction(q.f_fmax, q.x2, DT, DEFAULT_REVERSAL_THRESHOLD)], DT)
    ref_total, ref_branches = direct.run(x, return_branches=True)
    assert p.model_name == 'fractional_zener_berg' and p.branch_names == ['elastic', 'viscous', 'friction']
    np.testing.assert_allclose(total, ref_total, rtol=0, atol=1e-9 * np.max(np.abs(ref_total)))
    np.testing.assert_allclose(branches, ref_branches, rtol=0, atol=1e-9 * np.max(np.abs(ref_total)))


@pytest.mark.parametrize('name, model_name, names', [
    ('swing_arm_joint_case1', 'linear_spring + dashpot', ['k', 'c']),
])
def test_a_parameter_set_of_another_model_type_runs_as_its_model_file(name, model_name, names):
    """Any parameter set runs online (one model system): as the ModelSpec it describes, like a model file."""
    p = OnlinePredictor(ModelChoice(parameter_set=name))
    assert isinstance(p.params, ModelFileParams) and p.model_name == model_name
    assert list(p.params.as_dict()) == names and p.parameter_set == name
    assert str(p.params).startswith(f'parameter set {name} ')
    expected = parameter_set_info(name)['temperature']
    assert p.temperature == expected or (math.isnan(p.temperature) and math.isnan(expected))
    x = displacement()
    total, _ = run_batches(p, x)
    np.testing.assert_allclose(total, build_model(name, DT).run(x), rtol=1e-12, atol=1e-8)


def test_a_changed_parameter_is_checked_even_when_the_current_source_does_not_use_it():
    """element_model's run-time check (ModelChoice.checked): a later switch of ``source`` must never meet a bad value,
    and the error names the parameter."""
    good = ModelChoice(source='temperature', temperature=10.0)
    assert good.checked(['temperature'])[2] == 10.0
    with pytest.raises(ChoiceError) as err:      # not used now (source temperature), refused all the same
        ModelChoice(source='temperature', parameter_set='no_such_set').checked(['parameter_set'])
    assert err.value.field == 'parameter_set' and 'no_such_set' in str(err.value)
    with pytest.raises(ChoiceError) as err:
        ModelChoice(values={'k0': 1.0}).checked(['values.k0'])
    assert err.value.field.startswith('values.')
    with pytest.raises(ChoiceError) as err:
        ModelChoice(source='wishful').checked(['source'])
    assert err.value.field == 'source' and "'wishful' is not one of parameter_set" in str(err.value)
    # a value nobody changed is not judged: the current source's own (parameter_set) is the running model's
    assert ModelChoice(values={'k0': 1.0}).checked(['temperature'])[1] == 'swing_arm_joint_20C'
