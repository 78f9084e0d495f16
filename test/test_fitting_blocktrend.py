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

"""Seed 004's per-block identification and operating-point trend (rubber_rig.fitting.blocktrend) on synthetic
preloaded sines: x = x0 + A sin(2 pi f t), x0 = -1.1 mm, 1 kHz, force from Eq. 6 with known K1(f, A), K3, b plus
5 N white load-cell noise (numpy only, no rig)."""
import numpy as np
import pytest

from rubber_rig.fitting.blocks import BlockResult, split_blocks
from rubber_rig.fitting.blocktrend import fit_block, fit_blocks, fit_trend, per_block_report
from rubber_rig.fitting.data import RunData
from rubber_rig.models.trend import trend_value

DT = 1e-3
X0 = -1.1e-3
NOISE = 5.0                   # [N] load-cell sigma
# K1 [N/m]: quadratic in A [m], linear in f [Hz] (about Table 2's 2.7 ... 0.7 kN/mm)
K1_TABLE = [[3.8e6, -5.5e9, 2.3e12], [-2.0e4, -1.0e8, 2.0e11]]
K3 = 4.86e12                  # [N/m^3] (4.86 kN/mm^3)
B_PER_A = 1.128e6             # [N/m]: b = 1.128e6 A (Fig. 5: 0.3385 kN at 0.3 mm)
FREQUENCIES = (2.0, 4.0, 6.0, 8.0, 10.0)
AMPLITUDES = (0.3e-3, 0.5e-3, 0.7e-3)
CYCLES = 5


def _truth(f, a):
    return {'K1': trend_value(K1_TABLE, f, a), 'K3': K3, 'b': B_PER_A * a}


def _force(x, f, a, t, cubic=True):
    p = _truth(f, a)
    u = (x - X0) / a
    ellipse = np.sign(np.cos(2 * np.pi * f * t)) * np.sqrt(np.maximum(0.0, 1.0 - u * u))
    return p['K1'] * x + (p['K3'] * x ** 3 if cubic else 0.0) + p['b'] * ellipse


def _case(f, a, rng, x_noise=0.0, cycles=CYCLES):
    """Record of cycles + 2 periods; the block is the middle `cycles` periods."""
    per = int(round(1.0 / (f * DT)))
    t = np.arange(per * (cycles + 2)) * DT
    x = X0 + a * np.sin(2 * np.pi * f * t)
    force = _force(x, f, a, t) + rng.normal(0.0, NOISE, t.size)
    block = BlockResult(index=0, start=per, stop=per * (cycles + 1), cycles=cycles, skipped_cycles=1,
                        frequency=f, amplitude=a, mean=X0, k_dyn=0.0, loss_angle=0.0, damping=0.0, energy=0.0,
                        c_eq=0.0, recording=f'{f:g}Hz_{a * 1e3:g}mm')
    return x + rng.normal(0.0, x_noise, t.size) if x_noise else x, force, block


@pytest.fixture(scope='module')
def grid_rows():
    rng = np.random.default_rng(2004)
    rows = []
    for f in FREQUENCIES:
        for a in AMPLITUDES:
            x, force, block = _case(f, a, rng)
            rows.append(fit_block(x, force, DT, block))
    return rows


def test_per_block_recovery(grid_rows):
    worst = {'K1': 0.0, 'K3': 0.0, 'b': 0.0}
    for row in grid_rows:
        truth = _truth(row['frequency'], row['amplitude'])
        for name, tol in (('K1', 0.02), ('K3', 0.10), ('b', 0.02)):
            err = row[name] / truth[name] - 1
            worst[name] = max(worst[name], abs(err))
            assert abs(row[name] - truth[name]) < 3 * row['sigma'][name], (name, row['frequency'], row['amplitude'])
            assert abs(err) < tol, (name, row['frequency'], row['amplitude'], err)
        assert 0.6 < row['chi2_per_dof'] < 1.5
        assert row['noise'] == pytest.approx(NOISE, rel=0.2)
        assert row['residual_rms'] == pytest.approx(NOISE, rel=0.1)
        assert abs(row['offset']) < 3 * row['sigma']['offset']
        assert row['mean'] == X0 and row['recording']
    print('worst relative errors:', {k: f'{v:.2%}' for k, v in worst.items()})


def test_preload_correlates_k1_and_k3(grid_rows):
    for row in grid_rows:
        corr = row['correlation']
        assert set(corr) == {'offset-K1', 'offset-K3', 'offset-b', 'K1-K3', 'K1-b', 'K3-b'}
        assert corr['K1-K3'] < -0.9          # nearly collinear over x0 +- A under the preload
        assert abs(corr['K1-b']) < 0.1       # the ellipse is odd in time, the polynomial even


def test_fifth_order_is_optional():
    x, force, block = _case(2.0, 0.3e-3, np.random.default_rng(5))
    row = fit_block(x, force, DT, block, orders=(1, 3, 5))
    assert {'K1', 'K3', 'K5'} <= set(row['sigma'])
    assert abs(row['K5']) < 3 * row['sigma']['K5']
    with pytest.raises(ValueError, match='orders'):
        fit_block(x, force, DT, block, orders=(0, 1))
    with pytest.raises(ValueError, match='twice'):
        fit_block(x, force, DT, block, orders=(1, 1))


def test_missing_cubic_term_gives_large_chi2():
    x, force, block = _case(6.0, 0.5e-3, np.random.default_rng(6))
    full = fit_block(x, force, DT, block, orders=(1, 3))
    linear = fit_block(x, force, DT, block, orders=(1,))
    assert 'K3' not in linear
    assert linear['chi2_per_dof'] > 100
    assert linear['sigma']['K1'] > 10 * full['sigma']['K1']     # sigmas scaled by sqrt(chi2/dof)


def test_displacement_noise_at_turning_points():
    """Noise on x makes the velocity sign chatter near the extremes; the ellipse is ~0 there."""
    rng = np.random.default_rng(7)
    for f, a in ((2.0, 0.3e-3), (10.0, 0.7e-3)):
        x, force, block = _case(f, a, rng, x_noise=0.02e-6)
        row = fit_block(x, force, DT, block)
        truth = _truth(f, a)
        assert row['b'] == pytest.approx(truth['b'], rel=0.005)
        assert row['K1'] == pytest.approx(truth['K1'], rel=0.02)


def test_trend_recovers_the_k1_table(grid_rows):
    trend = fit_trend(grid_rows, 'K1', f_degree=1, a_degree=2)
    c, s = np.array(trend['coefficients']), np.array(trend['sigma'])
    assert c.shape == (2, 3) and trend['f_degree'] == 1 and trend['a_degree'] == 2
    assert np.all(np.abs(c - np.array(K1_TABLE)) < 3 * s), (c - np.array(K1_TABLE)) / s
    assert trend['chi2_per_dof'] < 2 and not trend['warnings'] and not trend['notes']
    assert len(trend['residuals']) == len(grid_rows) and np.max(np.abs(trend['residuals'])) < 0.02
    # usable by the pad model, and close to the truth over the whole grid
    ff, aa = np.meshgrid(FREQUENCIES, AMPLITUDES)
    assert np.allclose(trend_value(trend['coefficients'], ff, aa), trend_value(K1_TABLE, ff, aa), rtol=0.01)
    # the paper's form (cubic in f): the true table padded with zeros lies within 3 sigma
    cubic = fit_trend(grid_rows, 'K1')
    padded = np.zeros((4, 3))
    padded[:2] = K1_TABLE
    assert cubic['f_degree'] == 3 and cubic['a_degree'] == 2
    assert np.all(np.abs(np.array(cubic['coefficients']) - padded) < 3 * np.array(cubic['sigma']))


def test_trend_lowers_degrees_with_few_operating_points(grid_rows):
    two_amplitudes = [r for r in grid_rows if r['amplitude'] < 0.6e-3]
    trend = fit_trend(two_amplitudes, 'K1', f_degree=1, a_degree=2)
    assert trend['a_degree'] == 1 and np.array(trend['coefficients']).shape == (2, 2)
    assert any('amplitude' in n and 'lowered' in n for n in trend['notes'])
    one_frequency = [r for r in grid_rows if r['frequency'] == 2.0]
    trend = fit_trend(one_frequency, 'K1')
    assert trend['f_degree'] == 0 and trend['a_degree'] == 2
    assert any('frequenc' in n for n in trend['notes'])
    assert any('no degrees of freedom' in w for w in trend['warnings'])   # 3 values, 3 coefficients


def test_trend_warns_when_it_misses_the_data(grid_rows):
    trend = fit_trend(grid_rows, 'K1', f_degree=1, a_degree=0)   # K1 changes 3x with amplitude
    assert trend['chi2_per_dof'] > 2
    assert any('chi2/dof' in w for w in trend['warnings'])


def test_split_blocks_and_fit_blocks():
    """Two blocks in one record, cut by split_blocks from the block index channel."""
    rng = np.random.default_rng(8)
    xs, fs, index = [], [], []
    for k, (f, a) in enumerate(((4.0, 0.3e-3), (8.0, 0.7e-3))):
        t = np.arange(int(round(8 / (f * DT)))) * DT
        x = X0 + a * np.sin(2 * np.pi * f * t)
        xs.append(x)
        fs.append(_force(x, f, a, t) + rng.normal(0.0, NOISE, t.size))
        index.append(np.full(t.size, k))
    x, force = np.concatenate(xs), np.concatenate(fs)
    program = [{'frequency': 4.0, 'amplitude': 0.3e-3}, {'frequency': 8.0, 'amplitude': 0.7e-3}]
    report = split_blocks(x, force, DT, block_index=np.concatenate(index), program_blocks=program, settle_cycles=1)
    assert len(report.blocks) == 2
    run = RunData(name='synthetic', dt=DT, displacement=x, force=force)
    rows = fit_blocks([(run, report.blocks)])
    assert [r['recording'] for r in rows] == ['synthetic', 'synthetic']
    for row in rows:
        truth = _truth(row['frequency'], row['amplitude'])
        assert row['K1'] == pytest.approx(truth['K1'], rel=0.02)
        assert row['K3'] == pytest.approx(truth['K3'], rel=0.10)
        assert row['b'] == pytest.approx(truth['b'], rel=0.02)
        assert row['chi2_per_dof'] < 1.5


def test_report_in_paper_units(grid_rows):
    trends = [fit_trend(grid_rows, 'K1', f_degree=1), fit_trend(grid_rows, 'K3', 0, 0)]
    text = per_block_report(grid_rows, trends)
    assert 'K1 [kN/mm]' in text and 'K3 [kN/mm^3]' in text and 'b [kN]' in text and 'A [mm]' in text
    assert '4.86' in text            # K3 in kN/mm^3
    assert '-1.1000' in text         # x0 in mm
    assert 'Trend of K1' in text and 'Trend of K3' in text
    assert len([ln for ln in text.splitlines() if ln.strip().startswith(('2.000', '10.000'))]) == 6
    assert per_block_report(grid_rows, {t['name']: t for t in trends}) == text
