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

"""The node suite with real rclpy + Fast DDS in-process: a short program on the simulated rig (unpaced, so it
runs faster than real time with identical waveform and physics), through rig_driver, excitation,
element_model and recorder; assertions on what was published and recorded.

Tolerances: the simulated sensors have 2 N force noise and 0.2 um displacement noise (config/rig_sim.yaml);
the model is driven by the *measured* displacement, so its prediction carries k_dyn x 0.2 um ~ 3 N of the
displacement noise on top: residual RMS ~ 3.6 N when specimen and model are equal.
"""
import math

import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter

from msg_defs.msg import ModelParameters, RigStatus
from msg_defs.srv import RecorderControl
from rubber_rig.excitation import Program
from rubber_rig.models import load_parameter_set, parameters_at_temperature, steady_state_properties
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes import topics
from rubber_rig.nodes.auth import SAMPLES
from rubber_rig.recording import load_recording

from support.suite import (
    DISP_NOISE,
    FORCE_NOISE,
    PROGRAM,
    RATE,
    by_sequence,
    run_program,
    start_suite,
)


@pytest.fixture(scope='module')
def suite(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('suite')
    launcher, nodes = start_suite(tmp)
    try:
        mon = nodes['monitor']
        result = run_program(launcher, mon, PROGRAM)
        # the model (unpaced: it runs behind the rig) has predicted every sample the rig published
        assert launcher.wait_for(lambda: mon.stats['prediction'].next is not None
                                 and mon.stats['prediction'].next >= mon.stats['samples'].next, 10.0), \
            (mon.stats['prediction'].as_dict(), mon.stats['samples'].as_dict())
        stop = mon.recorder(RecorderControl.Request.STOP)
        assert launcher.wait_for(stop.done, 30.0)
        nodes['result'] = result
        nodes['mcap'] = stop.result().file
        nodes['launcher'] = launcher
        yield nodes
    finally:
        launcher.shutdown()


@pytest.mark.ros
def test_program_completes_with_block_summaries(suite):
    result = suite['result']
    assert result.success, result.message
    assert [b.name for b in result.blocks] == ['a', 'b']
    for b, target in zip(result.blocks, (0.5e-3, 1.0e-3), strict=False):
        assert b.completed
        assert b.target_amplitude == pytest.approx(target)
        # open loop through the 80 Hz actuator: amplitude error at 2-5 Hz well below 1 %
        assert b.achieved_amplitude == pytest.approx(target, rel=0.01)


@pytest.mark.ros
def test_setpoints_follow_the_program_and_reach_the_rig_in_time(suite):
    mon = suite['monitor']
    program = Program.from_yaml_text(PROGRAM)
    expected = program.setpoints(RATE)
    seq, sp = by_sequence(mon.messages['setpoints'], 'displacement')
    assert seq[0] == 0 and np.all(np.diff(seq) == 1), 'setpoint stream must be contiguous'
    assert len(sp) >= len(expected)
    np.testing.assert_allclose(sp[:len(expected)], expected, rtol=0, atol=1e-12)
    assert np.all(sp[len(expected):] == expected[-1])           # after the end: hold the last value
    starts = program.block_starts(RATE)
    for m in mon.messages['setpoints']:
        if m.first_sequence < len(expected):
            assert m.block_index == np.searchsorted(starts, m.first_sequence, side='right') - 1
    # the controller applied exactly these setpoints, sample by sample (to the 0.1 um resolution of the CAN
    # setpoint signal): the driver never starved
    sseq, applied = by_sequence(mon.messages['samples'], 'setpoint')
    inside = sseq < len(expected)
    np.testing.assert_array_equal(sseq[inside], np.arange(len(expected)))
    np.testing.assert_allclose(applied[inside], expected[sseq[inside]], rtol=0, atol=0.5e-7 + 1e-12)


@pytest.mark.ros
def test_no_sample_lost_between_driver_model_and_monitor(suite):
    stats = {k: v.as_dict() for k, v in suite['monitor'].stats.items()}
    for name in ('samples', 'prediction', 'setpoints'):
        assert stats[name]['gaps'] == 0 and stats[name]['missing'] == 0, (name, stats[name])
    assert stats['prediction']['samples'] == stats['samples']['samples']
    assert suite['monitor'].status.frames_lost == 0


@pytest.mark.ros
def test_prediction_agrees_with_measurement_within_the_noise(suite):
    mon = suite['monitor']
    preds = mon.messages['prediction']
    seq, residual = by_sequence(preds, 'residual')
    _, measured = by_sequence(preds, 'measured_force')
    _, predicted = by_sequence(preds, 'predicted_force')
    np.testing.assert_allclose(residual, measured - predicted, atol=1e-9)
    program = Program.from_yaml_text(PROGRAM)
    steady = (seq >= 1000) & (seq < program.n_samples(RATE))   # after the fractional/friction start-up
    k = 1.55e7                                                   # K_dyn at 2-5 Hz [N/m]
    expected_rms = math.hypot(FORCE_NOISE, k * DISP_NOISE)
    rms = float(np.sqrt(np.mean(residual[steady] ** 2)))
    assert rms < 1.5 * expected_rms, f'residual RMS {rms:.2f} N vs noise {expected_rms:.2f} N'
    # no bias beyond the noise: Berg friction driven by a noisy displacement sees extra velocity reversals near
    # the turning points, which shifts the friction force by a fraction of the noise level
    assert abs(float(np.mean(residual[steady]))) < 0.5 * expected_rms
    assert np.max(np.abs(measured[steady])) > 6e3     # the signal is kN, the residual a few N
    # branch forces add up to the prediction
    m = preds[len(preds) // 2]
    total = sum(conv.as_array(b.force) for b in m.branches)
    assert [b.name for b in m.branches] == ['elastic', 'viscous', 'friction']
    np.testing.assert_allclose(total, conv.as_array(m.predicted_force), rtol=1e-9, atol=1e-6)


def test_online_predictor_friction_deadband_keeps_the_loop_on_noisy_displacement():
    """ROS-free: the predictor runs on the measured displacement (0.2 um noise) in 50-sample batches. With the
    default reversal deadband (10x the noise) the friction branch dissipates what it does on the true
    displacement; with the paper's rule (0) noise reversals cut the loop by ~10 %."""
    from rubber_rig.models import build_model
    from rubber_rig.online.predictor import DEFAULT_REVERSAL_THRESHOLD, ModelChoice, OnlinePredictor

    from support.signals import cycle_energy, noisy_sine
    dt, per_cycle = 1e-3, 2000
    x, noisy = noisy_sine(seed=5, cycles=8, dt=dt, frequency=0.5, amplitude=0.5e-3, noise=DISP_NOISE)
    assert DEFAULT_REVERSAL_THRESHOLD == pytest.approx(10 * DISP_NOISE)
    params = load_parameter_set('seed000_20C')
    true_friction = build_model(params, dt).run(x, return_branches=True)[1][2]

    reference = cycle_energy(x, true_friction, per_cycle, cycles=1)
    got = {}
    for threshold in (DEFAULT_REVERSAL_THRESHOLD, 0.0):
        p = OnlinePredictor(ModelChoice(friction_reversal_threshold=threshold))
        branches = np.concatenate([p.process(i, dt, noisy[i:i + 50])[1] for i in range(0, x.size, 50)], axis=1)
        assert p.model.elements[1].reversal_threshold == threshold
        got[threshold] = cycle_energy(noisy, branches[2], per_cycle, cycles=1) / reference - 1
    assert abs(got[DEFAULT_REVERSAL_THRESHOLD]) < 0.02 and got[0.0] < -0.08, got
    with pytest.raises(ValueError, match='friction_reversal_threshold'):
        ModelChoice(friction_reversal_threshold=-1e-6).resolve()


@pytest.mark.parametrize('choice, field', [
    (dict(source='values', values=dict(load_parameter_set('seed000_20C').as_dict(), alpha=1.5)), 'values.alpha'),
    (dict(source='values', values=dict(load_parameter_set('seed000_20C').as_dict(), k_inf=1.0)), 'values.k_inf'),
    (dict(source='values', values=dict(load_parameter_set('seed000_20C').as_dict(), tau=float('nan'))),
     'values.tau'),
    (dict(source='parameter_set', parameter_set='/nonexistent.yaml:fit_20C'), 'parameter_set'),
    (dict(source='parameter_set', parameter_set='seed000_nope'), 'parameter_set'),
    (dict(source='temperature', temperature=35.0), 'temperature'),
    (dict(source='telepathy'), 'source'),
    (dict(friction_reversal_threshold=float('inf')), 'friction_reversal_threshold'),
])
def test_an_invalid_model_choice_names_the_field_at_fault(choice, field):
    """ROS-free: the error carries the element_model parameter it concerns (no parsing of its message)."""
    from rubber_rig.online.predictor import ChoiceError, ModelChoice
    with pytest.raises(ChoiceError) as err:
        ModelChoice(**choice).resolve()
    assert err.value.field == field, str(err.value)


@pytest.mark.ros
def test_cycle_metrics_match_the_analytic_steady_state(suite):
    """Steady full-amplitude cycles vs seed 000 Eq. 17-27. Tolerances: the model library's time-domain steady
    state is within 0.5 % of the analytic storage stiffness (its documented bound), so K_dyn within 0.6 %,
    C_eq within 1 %; measurement and model (same specimen) agree to the noise: 0.1 % and 0.5 %. Cycles cut
    across a taper (frequency off by more than 0.5 %) are not steady and are left out."""
    mon = suite['monitor']
    params = load_parameter_set('seed000_20C')
    checked = 0
    blocks = ((0, 5.0, 0.5e-3), (1, 2.0, 1.0e-3))

    def steady(block, f, amp):
        return [c for c in mon.cycle_metrics if c.block_index == block
                and abs(c.amplitude - amp) < 0.02 * amp and abs(c.frequency - f) < 0.005 * f]
    # each block has 4 cycles between its tapers; the last one's metrics follow the last prediction
    suite['launcher'].wait_for(lambda: all(len(steady(*b)) >= 4 for b in blocks), 5.0)
    for block, f, amp in blocks:
        cycles = steady(block, f, amp)
        assert len(cycles) >= 4, (f'block {block}: only {len(cycles)} steady cycles of (f [Hz], amplitude [mm]) '
                                  + str([(round(c.frequency, 4), round(c.amplitude * 1e3, 4))
                                         for c in mon.cycle_metrics if c.block_index == block]))
        for c in cycles:
            ref = steady_state_properties(params, c.frequency, c.amplitude)
            assert c.measured.k_dyn == pytest.approx(ref['k_dyn'], rel=0.006)
            assert c.model.k_dyn == pytest.approx(ref['k_dyn'], rel=0.006)
            assert c.measured.c_eq == pytest.approx(ref['c_eq'], rel=0.01)
            assert c.model.c_eq == pytest.approx(ref['c_eq'], rel=0.01)
            assert c.measured.k_dyn == pytest.approx(c.model.k_dyn, rel=1e-3)
            assert c.measured.c_eq == pytest.approx(c.model.c_eq, rel=5e-3)
            assert c.measured.loss_angle == pytest.approx(c.model.loss_angle, abs=math.radians(0.05))
            assert c.measured.energy_loop == pytest.approx(c.measured.energy_harmonic, rel=0.1)
            checked += 1
    assert checked >= 8


@pytest.mark.ros
def test_recording_holds_every_sample_and_prediction(suite):
    rec = load_recording(suite['mcap'])
    mon = suite['monitor']
    assert rec.samples_lost == 0 and not rec.gaps
    assert len(rec) == mon.stats['samples'].samples
    np.testing.assert_array_equal(rec.sequence, np.arange(len(rec)))
    assert np.all(np.isfinite(rec.prediction))
    np.testing.assert_allclose(rec.residual, rec.force - rec.prediction, atol=1e-6)
    assert rec.block_index[500] == 0


@pytest.mark.ros
def test_model_parameters_are_latched_and_follow_run_time_changes(suite):
    launcher, model = suite['launcher'], suite['model']
    late = Node('late_joiner', context=launcher.context)
    got = []
    late.create_subscription(ModelParameters, topics.MODEL_PARAMETERS, got.append, topics.LATCHED_QOS)
    launcher.spin(late)
    assert launcher.wait_for(lambda: got, 15.0), 'latched model_parameters not delivered to a late joiner'
    assert got[-1].parameter_set == 'swing_arm_joint_20C' and got[-1].model_name == 'fractional_zener_berg'
    values = dict(zip(got[-1].names, got[-1].values, strict=True))
    assert values['k0'] == pytest.approx(load_parameter_set('seed000_20C').k0)
    result = model.set_parameters_atomically([Parameter('source', value='temperature'),
                                              Parameter('temperature', value=-20.0)])
    assert result.successful, result.reason
    assert launcher.wait_for(lambda: got and got[-1].temperature == -20.0, 15.0)
    values = dict(zip(got[-1].names, got[-1].values, strict=False))
    assert values['k0'] == pytest.approx(parameters_at_temperature(-20.0).k0)
    model.set_parameters_atomically([Parameter('source', value='parameter_set')])


@pytest.mark.ros
def test_rig_status_is_latched_with_limits_and_rate(suite):
    status = suite['monitor'].status
    assert status.sample_rate == RATE
    assert status.limits.displacement_max == pytest.approx(5e-3)
    assert status.state in (RigStatus.STATE_RUNNING, RigStatus.STATE_HOLDING, RigStatus.STATE_IDLE)
    assert status.faults == 0


@pytest.mark.ros
@pytest.mark.slow
def test_element_model_runs_a_model_file_and_refuses_a_bad_one_at_run_time(tmp_path):
    """element_model as its own process with parameter_set:=<model file> (fractional Zener + Berg + cubic spring),
    fed sample batches from outside: the prediction is the file's model run on the sent displacement (to
    round-off), with the model's four branches; model_parameters names the file and its SI values. A bad model
    file set at run time is refused with a reason naming the file and the problem, and the model keeps running."""
    from pathlib import Path

    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    from msg_defs.msg import ModelPrediction, RigSampleBatch
    from rubber_rig.models import build_model
    from rubber_rig.testing.operator import Operator
    from rubber_rig.testing.processes import SuiteProcesses

    from support.suite import domain_id
    config = Path(__file__).resolve().parents[1] / 'config' / 'rig_sim.yaml'
    model_file = tmp_path / 'bushing_cubic.yaml'
    model_file.write_text('elements:\n'
                          '  - {type: fractional_zener, k0: 12.29 kN/mm, k_inf: 14.01 kN/mm, tau: 0.043 s, '
                          'alpha: 0.659}\n'
                          '  - {type: berg, x2: 1.41 mm, f_fmax: 4.57 kN}\n'
                          '  - {type: polynomial_spring, k3: 6e11 N/m^3}\n')
    bad_file = tmp_path / 'bad.yaml'
    bad_file.write_text('elements:\n  - {type: berg, x2: 1.41 kN, f_fmax: 4.57 kN}\n')
    ns, dt, size = '/model_file', 1e-3, 50
    t = np.arange(3000) * dt
    x = 1e-3 * np.sin(2 * np.pi * 2.0 * t) + np.random.default_rng(7).normal(0.0, DISP_NOISE, t.size)
    reference = build_model(str(model_file), dt, friction_reversal_threshold=2e-6)   # rig_sim.yaml's deadband
    expected, expected_branches = reference.run(x, return_branches=True)

    procs = SuiteProcesses(config, ns, domain_id(), tmp_path / 'logs',
                           {'element_model': {'parameter_set': str(model_file)}})
    procs.start('element_model')
    op = None
    try:
        assert procs.wait_started('element_model', 30.0), procs.log('element_model')[-3000:]
        op = Operator(ns, domain_id(), name='model_file_operator')
        preds, params = [], []
        op.node.create_subscription(ModelPrediction, topics.PREDICTION, preds.append, topics.STREAM_QOS)
        op.node.create_subscription(ModelParameters, topics.MODEL_PARAMETERS, params.append, topics.LATCHED_QOS)
        pub = op.node.create_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
        assert op.wait_for(lambda: params and pub.get_subscription_count() >= 1, 20.0), 'element_model not connected'
        p = params[-1]
        assert p.parameter_set == str(model_file), p.parameter_set
        assert p.model_name == 'fractional_zener + berg + polynomial_spring'
        values = dict(zip(p.names, p.values, strict=True))
        assert values == pytest.approx({'k0': 12.29e6, 'k_inf': 14.01e6, 'tau': 0.043, 'alpha': 0.659,
                                        'x2': 1.41e-3, 'f_fmax': 4570.0, 'k3': 6e11}, rel=1e-12)

        def send(lo, hi):
            for i in range(lo, hi, size):
                xb = x[i:i + size]
                pub.publish(op.sign(conv.sample_batch_msg(i, i * dt, dt, xb, np.zeros(xb.size), xb, 20.0, 0, 0),
                                    SAMPLES))   # as the rig's driver: signed with the rig's key

        def predicted_up_to(n):
            return lambda: preds and preds[-1].first_sequence + len(preds[-1].predicted_force) >= n

        half = x.size // 2
        send(0, half)
        assert op.wait_for(predicted_up_to(half), 20.0), 'no prediction for the first half'
        # the bad file at run time: refused, naming the file and the problem
        r = op.call('element_model/set_parameters', SetParameters, SetParameters.Request(parameters=[ParameterMsg(
            name='parameter_set', value=ParameterValue(type=ParameterType.PARAMETER_STRING,
                                                       string_value=str(bad_file)))]))
        assert r is not None and not r.results[0].successful
        reason = r.results[0].reason
        assert 'parameter_set' in reason and str(bad_file) in reason and 'x2' in reason, reason
        send(half, x.size)                      # the model file's model keeps running, state and all
        assert op.wait_for(predicted_up_to(x.size), 20.0), 'no prediction after the refused change'
        seq, got = by_sequence(preds, 'predicted_force')
        np.testing.assert_array_equal(seq, np.arange(x.size))
        np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-6)
        m = preds[len(preds) // 2]
        assert [b.name for b in m.branches] == ['elastic_1', 'viscous', 'friction', 'elastic_2']
        lo = m.first_sequence
        for b, ref in zip(m.branches, expected_branches[:, lo:lo + size], strict=True):
            np.testing.assert_allclose(conv.as_array(b.force), ref, rtol=1e-10, atol=1e-6)
        assert params[-1].parameter_set == str(model_file)        # nothing else was published
    finally:
        if op is not None:
            op.close()
        procs.stop_all()
