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

"""Faults, bad input and the lifecycle of the node suite (real rclpy in-process, simulated rig)."""
import math

import numpy as np
import pytest
from rclpy.parameter import Parameter

from msg_defs.msg import RigStatus
from rubber_rig.launching.inprocess import InProcessLauncher
from rubber_rig.nodes.element_model_node import ElementModelNode
from rubber_rig.nodes.excitation_node import ExcitationNode
from rubber_rig.nodes.params import ParameterError, undeclared_overrides
from rubber_rig.nodes.recorder_node import RecorderNode
from rubber_rig.nodes.rig_driver_node import RigDriverNode

from support.suite import CONFIG, RATE, by_sequence, domain_id, run_program, start_suite

pytestmark = pytest.mark.ros   # every test here runs nodes with real rclpy

LONG_SINE = """
name: long_sine
blocks:
  - {name: s, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 30, taper_cycles: 1}
"""


def test_injected_fault_drives_the_driver_to_fault_with_the_safe_ramp(tmp_path):
    # the displacement transducer freezes 1.5 s into the run (rig time) while the command keeps moving
    faults = "[{type: stuck_sensor, sensor: displacement, start: 1.5}]"
    launcher, nodes = start_suite(tmp_path, driver={'sim.faults': faults}, recorder=False)
    with launcher:
        mon = nodes['monitor']
        result = run_program(launcher, mon, LONG_SINE)
        assert not result.success
        assert 'fault' in result.message and 'sensor' in result.message, result.message
        assert launcher.wait_for(lambda: mon.status.state == RigStatus.STATE_FAULT, 30.0), mon.status.state_name
        assert mon.status.faults & RigStatus.FAULT_SENSOR
        assert any('stuck' in m for m in mon.status.fault_messages)
        # the controller ramps from wherever the sine was to rest: no step, velocity bounded, ends at zero
        assert launcher.wait_for(lambda: mon.stats['samples'].samples and abs(
            mon.messages['samples'][-1].setpoint[-1]) < 1e-7, 30.0), 'no ramp to rest'
        seq, u = by_sequence(mon.messages['samples'], 'setpoint')
        fault_at = int(1.5 * RATE)
        assert seq[-1] > fault_at + 50
        du = np.abs(np.diff(u))
        sine_step = 2 * math.pi * 5.0 * 1e-3 / RATE          # largest per-sample step of the 5 Hz, 1 mm sine
        assert du.max() <= 1.05 * sine_step + 1e-7, 'the command stepped'
        ramp = u[seq > fault_at]
        assert abs(ramp[-1]) < 1e-7
        # after the fault no further program setpoints are applied: the end is the ramp's, not the sine's
        moving = np.nonzero(np.abs(u) >= 1e-6)[0]
        assert seq[moving[-1]] > fault_at and u.size - moving[-1] >= 4     # ramped after the fault, ends at rest
        # and nothing is moved by a new program until the fault is reset
        refused = run_program(launcher, mon, LONG_SINE)
        assert not refused.success and 'fault' in refused.message


def test_bad_parameters_are_refused_with_errors_naming_them():
    with InProcessLauncher([CONFIG], domain_id=domain_id()) as launcher:
        model = launcher.start(ElementModelNode)
        result = model.set_parameters([Parameter('values.alpha', value=1.5)])[0]
        assert not result.successful and 'values.alpha' in result.reason      # descriptor range
        result = model.set_parameters([Parameter('values.k_inf', value=1.0e7)])[0]   # below k0 = 1.229e7
        assert not result.successful
        assert result.reason.startswith('values.k_inf:') and 'k0' in result.reason
        result = model.set_parameters([Parameter('parameter_set', value='seed000_99C')])[0]
        assert not result.successful and result.reason.startswith('parameter_set:') and 'seed000_20C' in result.reason
        result = model.set_parameters([Parameter('temperature', value=35.0)])[0]
        assert not result.successful and 'temperature' in result.reason
        assert model.get_parameter('values.alpha').value == pytest.approx(0.659)   # unchanged
        assert model.predictor.params.alpha == pytest.approx(0.659)
        assert model.predictor.choice.friction_reversal_threshold == pytest.approx(2e-6)   # config/rig_sim.yaml
        for bad in (-1e-6, 1e-3):
            result = model.set_parameters([Parameter('friction_reversal_threshold', value=bad)])[0]
            assert not result.successful and 'friction_reversal_threshold' in result.reason
        assert model.predictor.choice.friction_reversal_threshold == pytest.approx(2e-6)
        assert model.set_parameters([Parameter('friction_reversal_threshold', value=3e-6)])[0].successful
        assert model.predictor.choice.friction_reversal_threshold == pytest.approx(3e-6)   # next rebuild uses it
        with pytest.raises(ParameterError, match="'friction_reversal_threshold'"):
            launcher.start(ElementModelNode, {'friction_reversal_threshold': -1.0})

        with pytest.raises(ParameterError, match="'limits.displacement_min'"):
            launcher.start(RigDriverNode, {'autostart': False, 'limits.displacement_min': 0.01})
        with pytest.raises(ParameterError, match="'sample_rate'.*out of range"):
            launcher.start(RigDriverNode, {'autostart': False, 'sample_rate': 50000.0})
        with pytest.raises(ParameterError, match="'sim.faults'.*sim.faults\\[0\\].type.*meteor"):
            launcher.start(RigDriverNode, {'autostart': False, 'sim.faults': '[{type: meteor}]'})
        # every error of the core configuration names the parameter it is in (ConfigError.field -> parameter)
        for params, name in (({'can.bus_options': '[1, 2]'}, 'can.bus_options'),
                             ({'can.bus_options': '{a: [1'}, 'can.bus_options'),
                             ({'heartbeat_period': 0.3}, 'heartbeat_period'),   # not below watchdog_timeout 0.25
                             ({'rest_position': 0.009}, 'rest_position'),
                             ({'sim.faults': '[{type: drop, probability: 2}]'}, 'sim.faults'),
                             ({'limits.velocity_max': 0.0}, 'limits.velocity_max')):
            with pytest.raises(ParameterError, match=f"^parameter '{name}' of node 'rig_driver'"):
                launcher.start(RigDriverNode, dict(params, autostart=False))
        with pytest.raises(ParameterError, match="'program'.*no_such_program"):
            launcher.start(ExcitationNode, {'program': 'no_such_program'})
        with pytest.raises(ParameterError, match="'values.k_inf'"):
            launcher.start(ElementModelNode, {'source': 'values', 'values.k_inf': 1.0e6})


def test_every_key_of_the_shipped_configs_is_a_declared_parameter_and_typos_are_reported(tmp_path):
    # rclpy ignores an undeclared key silently; every key of the shipped configs must reach its node
    for config in (CONFIG, CONFIG.replace('rig_sim.yaml', 'rig_can.yaml')):
        with InProcessLauncher([config], domain_id=domain_id()) as launcher:
            for factory in (RigDriverNode, ExcitationNode, ElementModelNode, RecorderNode):
                extra = {RigDriverNode: {'autostart': False}, RecorderNode: {'output_dir': str(tmp_path)}}
                node = launcher.start(factory, extra.get(factory, {}))
                assert undeclared_overrides(node) == [], (config, factory.__name__)
                if hasattr(node, 'close'):
                    node.close()
    with InProcessLauncher([CONFIG], domain_id=domain_id()) as launcher:
        model = launcher.start(ElementModelNode, {'frition_reversal_threshold': 2e-6})
        assert undeclared_overrides(model) == ['frition_reversal_threshold']
        assert model.predictor.choice.friction_reversal_threshold == pytest.approx(2e-6)   # the file's value stays


def test_bad_programs_are_refused_before_anything_moves(tmp_path):
    launcher, nodes = start_suite(tmp_path, recorder=False)
    with launcher:
        mon = nodes['monitor']
        bad_field = "blocks:\n  - {name: x, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 2.5}\n"
        result = run_program(launcher, mon, bad_field)
        assert not result.success and "block 0 'x'" in result.message and "'cycles'" in result.message
        too_big = "blocks:\n  - {name: big, waveform: sine, frequency: 1 Hz, amplitude: 8 mm, cycles: 2}\n"
        result = run_program(launcher, mon, too_big)
        assert not result.success and 'limits' in result.message
        # an absence cannot be waited for: give a stray setpoint or sample 0.3 s (300 samples) to show up
        launcher.wait_for(lambda: mon.stats['setpoints'].messages or mon.stats['samples'].samples, 0.3)
        assert mon.stats['setpoints'].messages == 0 and mon.stats['samples'].samples == 0


def test_rig_driver_lifecycle(tmp_path):
    with InProcessLauncher([CONFIG], domain_id=domain_id()) as launcher:
        driver = launcher.start(RigDriverNode, {'autostart': False, 'paced': False})
        samples = driver.resolve_topic_name('samples')
        assert driver.lifecycle_state == 'unconfigured' and driver.rig is None
        assert driver.count_publishers(samples) == 0 and driver.channels is None
        for _ in range(2):   # as the ros2/demos lifecycle talker: configure creates, cleanup destroys, and again
            driver.trigger_configure()
            assert driver.lifecycle_state == 'inactive' and driver.rig is not None
            assert launcher.wait_for(lambda: driver.count_publishers(samples) == 1, 5.0) and driver.channels is not None
            idle = driver.params.status_period       # the one timer: status, heartbeat, diagnostics; no bus reads
            assert driver.ticks.period == idle and not driver.active        # the bus is read only when active
            driver.trigger_activate()
            # unpaced, the driver's polls drive the simulator: polled every poll_period, no receiving thread
            assert driver.lifecycle_state == 'active' and driver.active and driver.rig.driver.io.receiver is None
            assert driver.ticks.period == driver.params.poll_period
            driver.trigger_deactivate()
            assert driver.lifecycle_state == 'inactive' and driver.ticks.period == idle and not driver.active
            driver.trigger_cleanup()
            assert driver.lifecycle_state == 'unconfigured' and driver.rig is None and driver.ticks.period == idle
            assert driver.channels is None and driver._frames_in is None and driver.pub_samples is None
            assert launcher.wait_for(lambda: driver.count_publishers(samples) == 0, 5.0)   # (the graph learns it)
        # paced (the default): a thread reads the bus and wakes the node per batch; the timer polls at the watchdog's
        # period only; deactivating stops the thread (what it read is taken), activating starts a new one
        paced = launcher.start(RigDriverNode, {'autostart': True}, node_name='rig_driver_paced')
        receiver = paced.rig.driver.io.receiver
        assert receiver is not None and receiver.running and paced.ticks.period == paced.rig.driver.tick_period
        # an idle controller sends no samples (no wake-up), but its heartbeats reach the driver through the thread
        assert launcher.wait_for(lambda: paced.rig.driver.counters['heartbeats_received'] > 3, 10.0)
        assert receiver.wakes == 0 and paced.rig.driver.faults == 0
        paced.trigger_deactivate()
        assert not receiver.running and paced.rig.driver.io.receiver is None and paced.ticks.period == idle
        paced.trigger_activate()
        assert paced.rig.driver.io.receiver.running and paced.rig.driver.io.receiver is not receiver
        # a bus that cannot be opened: configure fails and the node stays unconfigured
        bad = launcher.start(RigDriverNode, {'autostart': False, 'backend': 'socketcan', 'can.channel': 'nocan7'},
                             node_name='rig_driver_bad')
        bad.trigger_configure()
        assert bad.lifecycle_state == 'unconfigured' and bad.rig is None


def test_model_follows_the_rig_temperature_channel(tmp_path):
    """A 0 degC specimen, the model told to follow the rig's temperature channel (starting from 20 degC): it
    re-evaluates its parameters at the measured temperature and then predicts the cold specimen."""
    from rubber_rig.models import parameters_at_temperature

    from support.suite import by_sequence
    launcher, nodes = start_suite(tmp_path, recorder=False, driver={
        'sim.specimen.parameter_set': '', 'sim.specimen.temperature': 0.0, 'sim.temperature': 0.0})
    with launcher:
        model, mon = nodes['model'], nodes['monitor']
        assert model.set_parameters([Parameter('source', value='rig_temperature')])[0].successful
        result = run_program(launcher, mon, "blocks:\n  - {name: s, waveform: sine, frequency: 5 Hz, "
                                            "amplitude: 0.5 mm, cycles: 6, taper_cycles: 1}\n")
        assert result.success, result.message
        assert launcher.wait_for(lambda: mon.model_parameters is not None
                                 and abs(mon.model_parameters.temperature) < 0.5, 15.0)
        values = dict(zip(mon.model_parameters.names, mon.model_parameters.values, strict=False))
        cold = parameters_at_temperature(mon.model_parameters.temperature)
        assert values['k0'] == pytest.approx(cold.k0) and values['f_fmax'] == pytest.approx(cold.f_fmax)
        assert mon.model_parameters.parameter_set == ''
        seq, residual = by_sequence(mon.messages['prediction'], 'residual')
        late = seq > seq[-1] - 800        # the last 0.8 s (4 cycles), long after the switch to 0 degC
        rms = float(np.sqrt(np.mean(residual[late] ** 2)))
        assert rms < 10.0, f'residual {rms:.1f} N: the model did not follow the 0 degC specimen'


def test_amplitude_control_through_the_nodes_reaches_the_target_at_high_frequency(tmp_path):
    # the 80 Hz actuator attenuates a 30 Hz command by ~5 %; the excitation node's outer loop makes the
    # measured amplitude reach the target within 1 % (compensation_memory off: each block learns on its own).
    # The loop's latency is lead_time (the default 1.0 s, chosen to ride out 0.8 s stalls, issue 34), and the
    # achieved amplitude is the mean of the last half of the steady cycles: the blocks last 4 s so that half starts
    # a full second after the first correction can have reached the rig. A 1.33 s block ended 1.07 % short on a busy
    # CI machine with 0.7 s of lead: its last half began before the correction had arrived.
    program = """
name: amp
defaults: {taper_cycles: 2}
blocks:
  - {name: a, waveform: sine, frequency: 30 Hz, amplitude: 0.5 mm, cycles: 120}
  - {name: b, waveform: sine, frequency: 25 Hz, amplitude: 0.3 mm, cycles: 100}
"""
    launcher, nodes = start_suite(tmp_path, excitation={'compensation_memory': False}, recorder=False)
    with launcher:
        result = run_program(launcher, nodes['monitor'], program, amplitude_control=True)
        assert result.success, result.message
        assert nodes['excitation'].params.compensation_memory is False
        for block, target in zip(result.blocks, (0.5e-3, 0.3e-3), strict=False):
            print(block.name, block.achieved_amplitude / target - 1)
            assert block.achieved_amplitude == pytest.approx(target, rel=0.01), block.name
