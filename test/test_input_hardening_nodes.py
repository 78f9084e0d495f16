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

"""Bad input never takes the element_model node down: refused parameter changes, non-finite
and malformed sample batches, a restarted driver; and the simulated load cell reads NaN for a NaN force.
The predictor tests are ROS-free; the node ones use a real rclpy node in-process and call its callbacks."""
import math

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter

from rubber_rig.models import build_model, load_parameter_set
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes.element_model_node import ElementModelNode
from rubber_rig.nodes.params import ParameterError
from rubber_rig.online.predictor import ModelChoice, OnlinePredictor, batch_problem
from rubber_rig.rig.sim.plant import Sensor

DT, BATCH = 1e-3, 100


def sine(n, f=5.0, a=1e-3, start=0):
    return a * np.sin(2 * np.pi * f * (start + np.arange(n)) * DT)


def batches(x):
    return [(first, x[first:first + BATCH]) for first in range(0, x.size, BATCH)]


def predict(pred, stream):
    return {first: pred.process(first, DT, xb)[0] for first, xb in stream}


# -- predictor (ROS-free) ----------------------------------------------------------------------------------
def test_an_all_nan_batch_does_not_poison_later_predictions():
    x = sine(3000)
    clean = [(first, xb) for first, xb in batches(x) if first != 1000]      # the batch at 1000 was lost
    nan = [(first, np.full(BATCH, np.nan) if first == 1000 else xb) for first, xb in batches(x)]
    ref = predict(OnlinePredictor(ModelChoice()), clean)
    pred = OnlinePredictor(ModelChoice())
    got = predict(pred, nan)
    assert np.all(np.isnan(got[1000])) and pred.nonfinite_samples == BATCH
    for first, f in ref.items():                                             # skipped = as if the frames were lost
        assert np.all(np.isfinite(got[first]))
        np.testing.assert_allclose(got[first], f, rtol=1e-9, atol=1e-9 * np.max(np.abs(f)))
    assert np.max(np.abs(got[2900])) > 5e3                                    # still a real force [N]


def test_scattered_nan_and_inf_samples_are_skipped_and_predicted_nan():
    x = sine(2000)
    bad = np.zeros(x.size, bool)
    bad[[5, 6, 7, 333, 1234, 1999]] = True
    xs = x.copy()
    xs[bad] = [np.nan, np.inf, -np.inf, np.nan, np.nan, np.inf]
    pred = OnlinePredictor(ModelChoice())
    got = np.concatenate(list(predict(pred, batches(xs)).values()))
    # the reference sees the same batches without the bad samples
    ref_pred = OnlinePredictor(ModelChoice())
    ref = np.concatenate([ref_pred.process(first, DT, xb[~bad[first:first + BATCH]])[0]
                          for first, xb in batches(x)])
    assert np.array_equal(np.isnan(got), bad) and pred.nonfinite_samples == 6
    np.testing.assert_allclose(got[~bad], ref, rtol=1e-9, atol=1e-6)


def test_a_sequence_going_backwards_restarts_the_model():
    x = sine(1000)
    pred = OnlinePredictor(ModelChoice())
    predict(pred, batches(x))
    assert pred.goes_back(0) and not pred.goes_back(1000)
    again = pred.process(0, DT, x[:BATCH])[0]                      # the driver restarted its sequence
    fresh = OnlinePredictor(ModelChoice()).process(0, DT, x[:BATCH])[0]
    assert pred.restarts == 1
    np.testing.assert_array_equal(again, fresh)                    # from rest, not warmed on the old history


@pytest.mark.parametrize('args, why', [
    ((0, 1e-3, 10, 9), 'lengths differ'),
    ((0, 0.0, 10, 10), 'sample_period'),
    ((0, -1e-3, 10, 10), 'sample_period'),
    ((0, math.nan, 10, 10), 'sample_period'),
    ((0, math.inf, 10, 10), 'sample_period'),
    ((-5, 1e-3, 10, 10), 'first_sequence'),
])
def test_unusable_batches_are_named(args, why):
    assert why in batch_problem(*args)
    assert batch_problem(0, 1e-3, 10, 10) is None


def test_a_missing_parameter_file_is_a_value_error_naming_the_parameter_set():
    with pytest.raises(ValueError, match="parameter set '/nonexistent.yaml:fit_20C'.*no such parameter file"):
        ModelChoice(parameter_set='/nonexistent.yaml:fit_20C').resolve()


def test_the_load_cell_reads_nan_for_a_nan_force():
    sensor = Sensor(noise=1.0, offset=0.0, resolution=0.01, rng=np.random.default_rng(1))
    assert math.isnan(sensor.read(math.nan)) and math.isnan(sensor.read(math.inf))
    assert math.isnan(sensor.read(1e307))                          # beyond what the quantiser can count
    assert sensor.read(1000.0) == pytest.approx(1000.0, abs=5.0)  # and it goes on measuring


# -- the node (real rclpy, callbacks called directly) --------------------------------------------------------
@pytest.fixture
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


@pytest.fixture
def node(context):
    # the tests feed take_samples, the data path behind the signature check of on_samples (test_security_nodes)
    n = ElementModelNode(context=context, parameter_overrides=[Parameter('cycle_metrics', value=True)])
    n.published, n.metrics = [], []
    n.pub_prediction.publish = n.published.append
    n.pub_metrics.publish = n.metrics.append
    yield n
    n.destroy_node()


def write_set(path, **values):
    v = {**load_parameter_set('seed000_20C').as_dict(), **values}
    path.write_text('sets:\n  fit_20C:\n    model: seed000\n    values: {'
                    + ', '.join(f'{k}: {x!r}' for k, x in v.items()) + '}\n')
    return f'{path}:fit_20C'


@pytest.mark.ros
def test_bad_parameter_changes_are_refused_with_a_reason_and_the_model_keeps_running(node, tmp_path):
    before = node.predictor.params
    bad_yaml = tmp_path / 'bad.yaml'
    bad_yaml.write_text('sets: [unclosed\n')
    (tmp_path / 'a_directory.yaml').mkdir()
    cases = [([Parameter('parameter_set', value='/nonexistent.yaml:fit_20C')], 'no such parameter file'),
             ([Parameter('parameter_set', value=f'{bad_yaml}:fit_20C')], 'not valid YAML'),
             ([Parameter('parameter_set', value=write_set(tmp_path / 'neg.yaml', k0=-1.0))], 'k0'),
             ([Parameter('parameter_set', value=write_set(tmp_path / 'one.yaml') + 'x')], 'unknown parameter set'),
             ([Parameter('parameter_set', value=str(tmp_path / 'a_directory.yaml'))], 'no such parameter file'),
             ([Parameter('source', value='values'), Parameter('values.k_inf', value=1.0e6)], 'values.k_inf')]
    for params, why in cases:
        result = node.set_parameters_atomically(params)
        assert not result.successful, params
        assert why in result.reason and result.reason.split(':')[0] in (
            'parameter_set', 'values.k_inf'), result.reason
        assert node.predictor.params is before
    assert node.get_parameter('parameter_set').value == 'swing_arm_joint_20C'
    # a good file is read once, in the validating callback: removing it afterwards changes nothing
    good = write_set(tmp_path / 'good.yaml', k0=1.1e7)
    assert node.set_parameters_atomically([Parameter('parameter_set', value=good)]).successful
    (tmp_path / 'good.yaml').unlink()
    assert node.predictor.params.k0 == 1.1e7 and node.predictor.parameter_set == good
    node.take_samples(conv.sample_batch_msg(0, 0.0, DT, sine(BATCH), np.zeros(BATCH), sine(BATCH), 20.0, 0, 0))
    assert np.all(np.isfinite(node.published[-1].predicted_force))


@pytest.mark.ros
def test_a_bad_parameter_set_at_start_names_the_parameter(context):
    with pytest.raises(ParameterError, match="parameter 'parameter_set'.*no such parameter file"):
        ElementModelNode(context=context, parameter_overrides=[
            Parameter('parameter_set', value='/nonexistent.yaml:fit_20C')])


def stream(node, x, force, skip=(), first=0):
    for lo in range(0, x.size, BATCH):
        if lo + first in skip:
            continue
        s = slice(lo, lo + BATCH)
        node.take_samples(conv.sample_batch_msg(first + lo, (first + lo) * DT, DT, x[s], force[s], x[s], 20.0, 0, 0))


@pytest.mark.ros
def test_nan_batches_and_nan_forces_neither_crash_nor_poison_the_node(node):
    n = 8000
    x = sine(n, f=2.0)
    force = build_model('seed000_20C', DT).run(x)
    xs, fs = x.copy(), force.copy()
    xs[2000:2100] = np.nan                        # one all-NaN batch of displacement
    fs[4000:4100] = np.nan                        # a load cell that read NaN for a batch
    fs[5050] = np.inf
    stream(node, xs, fs)
    pred = np.concatenate([np.asarray(m.predicted_force) for m in node.published])
    assert pred.size == n and np.all(np.isnan(pred[2000:2100]))
    assert np.all(np.isfinite(pred[2100:])) and np.all(np.isfinite(pred[:2000]))
    assert node.predictor.nonfinite_samples == 100
    # the cycle metrics go on between the gaps (2 Hz; the detector restarts after each gap, and the last second
    # waits for setpoints that never come): cycles end in every finite stretch
    ends = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in node.metrics])
    for lo, hi in ((0.0, 2.0), (2.1, 4.0), (4.1, 5.05), (5.05, 7.0)):
        assert np.any((ends > lo) & (ends <= hi)), (lo, hi, ends)
    assert all(math.isfinite(m.measured.k_dyn) and math.isfinite(m.model.k_dyn) for m in node.metrics)


@pytest.mark.ros
def test_malformed_batches_are_dropped_and_a_restarted_driver_restarts_the_model(node):
    x = sine(1000)
    f = np.zeros(1000)
    node.take_samples(conv.sample_batch_msg(0, 0.0, DT, x[:10], f[:9], x[:10], 20.0, 0, 0))
    node.take_samples(conv.sample_batch_msg(0, 0.0, 0.0, x[:10], f[:10], x[:10], 20.0, 0, 0))
    node.take_samples(conv.sample_batch_msg(0, 0.0, -DT, x[:10], f[:10], x[:10], 20.0, 0, 0))
    node.take_samples(conv.sample_batch_msg(0, 0.0, math.nan, x[:10], f[:10], x[:10], 20.0, 0, 0))
    assert node.batches_dropped == 4 and node.published == []
    stream(node, x, f)
    stream(node, x[:200], f[:200])                 # sequence back to 0: a new run
    assert node.predictor.restarts == 1
    fresh = OnlinePredictor(ModelChoice()).process(0, DT, x[:BATCH])[0]
    np.testing.assert_array_equal(np.asarray(node.published[-2].predicted_force), fresh)


@pytest.mark.ros
def test_a_stale_or_foreign_batch_that_goes_back_does_not_restart_the_model(node):
    """One batch with an old sequence (a stale copy, another publisher) amid the driver's stream: ignored and
    counted, the model goes on as if it never came; a stream that goes on from the new point is a restart."""
    x = sine(1000)
    f = np.zeros(1000)
    stream(node, x[:500], f[:500])
    node.take_samples(conv.sample_batch_msg(100, 0.1, DT, x[:BATCH], f[:BATCH], x[:BATCH], 20.0, 0, 0))
    stream(node, x[500:], f[500:], first=500)
    assert node.predictor.restarts == 0 and node.stray_batches == 1
    pred = np.concatenate([np.asarray(m.predicted_force) for m in node.published])
    ref = OnlinePredictor(ModelChoice())
    clean = np.concatenate([ref.process(lo, DT, x[lo:lo + BATCH])[0] for lo in range(0, 1000, BATCH)])
    np.testing.assert_array_equal(pred, clean)
    assert [m.first_sequence for m in node.published] == list(range(0, 1000, BATCH))
