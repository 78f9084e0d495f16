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


"""The one safe envelope (rubber_rig.safety): the setpoint rule the driver applies to every batch and the program
pre-check reach the same verdict, each limit has one definition, and what the CAN frames carry never loosens it.
"""
import math
import time

import numpy as np
import pytest

from rubber_rig.excitation import Program, check_program
from rubber_rig.rig import ConfigError, RigConfig, open_rig
from rubber_rig.safety import LimitError, Limits, abort_ramp_velocity, setpoint_violation, stopping_positions
from rubber_rig.settings import described, violations

from support.rig import FAST

FS = 1000.0
LIMITS = Limits(displacement_min=-2.5e-3, displacement_max=2.5e-3, velocity_max=0.2, deceleration_max=100.0)


def test_setpoint_violation_names_the_first_broken_rule_and_its_sample():
    assert setpoint_violation(LIMITS, np.linspace(0, 1e-3, 50), FS, 0.0) is None
    bad = setpoint_violation(LIMITS, [0.0, 1e-5, math.nan, 9.0], FS, 0.0)
    assert (bad.kind, bad.index) == ('not_finite', 2)
    bad = setpoint_violation(LIMITS, [0.0, 1e-5, 2.6e-3], FS, 0.0)
    assert (bad.kind, bad.index) == ('displacement', 2) and 'outside the displacement limits' in bad.message
    # 0.21 m/s: one step of 0.21 mm at 1 kHz; from `previous` the first sample is the step
    bad = setpoint_violation(LIMITS, [0.21e-3, 0.22e-3], FS, 0.0)
    assert (bad.kind, bad.index) == ('velocity', 0) and 'velocity 0.21 m/s above velocity_max 0.2' in bad.message
    assert setpoint_violation(LIMITS, [0.21e-3, 0.22e-3], FS) is None          # no previous: the step is unknown
    # 0.19 m/s up to 2.48 mm: stopping at 100 m/s^2 takes 0.18 mm more: past 2.5 mm
    x = 2.1e-3 + 0.19e-3 * np.arange(1, 3)
    assert float(stopping_positions(x[-1], 0.19, 100.0, FS)) > 2.5e-3
    bad = setpoint_violation(LIMITS, x, FS, 2.1e-3)
    assert bad.kind == 'stopping' and 'could not stop inside the limits at deceleration_max 100' in bad.message


SHAPES = ('sine', 'triangle')


@pytest.mark.parametrize('shape', SHAPES)
def test_the_pre_check_refuses_exactly_what_the_streamed_check_refuses(shape):
    """60 programs per shape around the envelope's edges (amplitude, frequency, mean): check_program refuses a
    program if and only if streaming its setpoints in batches of 10 through setpoint_violation (what the driver
    does) finds a violation (which rule each names first depends on the batch it sees first)."""
    rng = np.random.default_rng(7)
    refused = 0
    for _ in range(60):
        a = rng.uniform(0.5e-3, 2.4e-3)
        f = rng.uniform(2.0, 30.0)
        mean = rng.uniform(-1.0e-3, 1.0e-3)
        p = Program.from_yaml_text(f'name: p\ninitial_position: {mean * 1e3:.5f} mm\nblocks:\n'
                                   f'  - {{waveform: {shape}, frequency: {f:.4f} Hz, amplitude: {a * 1e3:.5f} mm, '
                                   f'mean: {mean * 1e3:.5f} mm, cycles: 3, taper_cycles: 1}}\n')
        x = p.setpoints(FS)
        streamed = None
        prev = p.initial_position
        for lo in range(0, x.size, 10):
            streamed = setpoint_violation(LIMITS, x[lo:lo + 10], FS, prev)
            if streamed is not None:
                break
            prev = float(x[min(lo + 10, x.size) - 1])
        try:
            check_program(LIMITS, p, FS)
            pre = None
        except LimitError as exc:
            pre = str(exc)
        assert (pre is None) == (streamed is None), (shape, a, f, mean, pre, streamed)
        if pre is not None:
            refused += 1
    assert 5 <= refused <= 55                    # the sweep straddles the edge: both verdicts occur


def test_limit_ranges_and_choices_are_checked_from_their_description():
    assert described(RigConfig, 'sample_rate').range == (10.0, 20000.0)
    with pytest.raises(ConfigError, match="field 'sample_rate'.*5.0 Hz outside 10..20000 Hz"):
        RigConfig.from_dict({'sample_rate': 5.0})
    with pytest.raises(ConfigError, match="field 'stream_loss_action'.*'drop' is not one of: 'ramp', 'hold'"):
        RigConfig.from_dict({'stream_loss_action': 'drop'})
    # the frame carries the deceleration in steps of 2 m/s^2 and the ramp speed in whole mm/s: limits below
    # that would be rounded to something looser, so they are refused
    with pytest.raises(ConfigError, match="field 'limits.deceleration_max'.*outside 2..510"):
        RigConfig.from_dict({'limits': {'deceleration_max': 1.0}})
    with pytest.raises(ConfigError, match="field 'limits.velocity_max'.*outside 0.002..100"):
        RigConfig.from_dict({'limits': {'velocity_max': 1e-3}})
    assert violations(RigConfig()) == []
    # the same ranges hold for Limits built anywhere else (the driver's parameters, a RigLimits message, a test):
    # one description, one check
    with pytest.raises(LimitError, match="field 'deceleration_max': 1000.0 m/s\\^2 outside 2..510") as err:
        Limits(deceleration_max=1000.0)
    assert err.value.field == 'deceleration_max'
    with pytest.raises(LimitError, match="field 'velocity_max': 0.001 m/s outside 0.002..100"):
        Limits.from_dict({'velocity_max': 1e-3})
    with pytest.raises(LimitError, match="field 'force_max': -5.0 N outside 1..1e"):
        Limits(force_max=-5.0)
    assert abort_ramp_velocity(Limits(velocity_max=0.04)) == pytest.approx(0.02)
    assert abort_ramp_velocity(Limits(velocity_max=1.0)) == pytest.approx(0.05)   # RAMP_VELOCITY


@pytest.mark.parametrize('decel, sent', [(3.0, 2.0), (2.0, 2.0), (101.0, 100.0)])
def test_the_controller_never_brakes_harder_than_the_host_allows(decel, sent):
    """HostLimits carries multiples of 2 m/s^2: the driver rounds down, never to 0 (the controller's default of
    100 m/s^2), and the simulated controller ramps with what it received."""
    with open_rig(dict(FAST, limits={'deceleration_max': decel})) as rig:
        assert rig.wait_ready(5.0)
        deadline = time.monotonic() + 5.0
        while rig.sim.decel_max != sent and time.monotonic() < deadline:
            time.sleep(0.01)
        assert rig.sim.decel_max == pytest.approx(sent)
