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

"""`rubber-rig report`: PNG figures and one self-contained HTML page from a simulated-rig recording."""
import base64
import json
import re

import pytest

from rubber_rig.fitting.report import FIGURES as ALL_FIGURES

PNG = b'\x89PNG\r\n\x1a\n'
PROGRAM = {'name': 'report_test', 'defaults': {'taper_cycles': 1, 'cycles': 6, 'mean': 0.0},
           'blocks': [{'waveform': 'sine', 'amplitude': ['0.5 mm', '1 mm'], 'frequency': ['1 Hz', '4 Hz', '12 Hz']}]}
# seed 000 at 20 degC plus a cubic spring, with uncertainties and a fit record as rubber-rig fit writes them
CUBIC_MODEL = """
name: zener_berg_cubic
temperature: 20.0
fit:
  recordings: [run_20C.mcap]
  method: time
  chi2_per_dof: 4.2
  warnings: ['misfit: chi2/dof = 4.2, the model misses something the data show']
  notes: ['x2 and f_fmax are correlated (+0.99)']
  load_cell: {delay: 0.0, gain: 1.0, delay_estimated: 1.0e-4, delay_sigma: 2.0e-5}
elements:
- type: fractional_zener
  k0: 12.29 kN/mm
  k_inf: 14.01 kN/mm
  tau: 0.043
  alpha: 0.659
  sigma: {k0: 0.05 kN/mm, k_inf: 60000.0, tau: 0.001, alpha: 0.01}
- type: berg
  x2: 1.41 mm
  f_fmax: 4.57 kN
  sigma: {x2: 3.0e-5, f_fmax: 90.0}
- type: polynomial_spring
  k3: 6.0e+11
  sigma: {k3: 2.0e+11}
  interval_95: {k3: [2.08e+11, 9.92e+11]}
"""


# a simulated recording has no online cycle metrics: no 'cycles' figure (test_detectors_nodes checks it)
FIGURES = [f for f in ALL_FIGURES if f != 'cycles']


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    from rubber_rig.fitting.simulate import simulated_recording
    return simulated_recording(tmp_path_factory.mktemp('rep') / 'run_20C.mcap', PROGRAM, 'seed000_20C', 20.0,
                               force_noise=10.0)


def _check_report(files, outdir, n_blocks, figures=FIGURES):
    assert set(files) == set(figures) | {'html'}
    for name in figures:
        path = outdir / f'{name}.png'
        assert path.exists() and path.stat().st_size > 5000, name
        assert path.read_bytes()[:8] == PNG
    page = (outdir / 'report.html').read_text()
    images = re.findall(r'<img alt="(\w+)" src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert [a for a, _ in images] == list(figures)
    for alt, b64 in images:    # the embedded images are the PNG files themselves
        assert base64.b64decode(b64) == (outdir / f'{alt}.png').read_bytes()
    assert 'src="http' not in page and '<link' not in page      # self-contained
    # one row per analysed block in the block table (header row + blocks)
    table = page.split('<h2>Blocks</h2>')[1].split('</table>')[0]
    assert table.count('<tr>') == n_blocks + 1
    # the residual panels under the loops and the error bars of K_dyn / C_eq are described with their figures
    loops = page.split('alt="loops"')[1].split('<h2>')[0]
    assert 'residual F_model - F_measured' in loops and '+-2 sigma_F' in loops
    assert '1-sigma error bars' in page.split('alt="kdyn_ceq"')[1].split('<h2>')[0]
    return page


def _param_rows(page):
    """{parameter: [cells]} of the parameter table."""
    table = page.split('<table class="params">')[1].split('</table>')[0]
    rows = re.findall(r'<tr><td class="l">(\w+)</td>(.*?)</tr>', table)
    return {name: re.findall(r'<td[^>]*>(.*?)</td>', cells) for name, cells in rows}


def test_report_with_a_fitted_model_file(recording, tmp_path, capsys):
    from rubber_rig.cli.main import main
    fitted = tmp_path / 'fit.yaml'
    assert main(['fit', str(recording), '-o', str(fitted), '--method', 'harmonic', '--no-progress']) == 0
    capsys.readouterr()
    out = tmp_path / 'report'
    assert main(['report', str(recording), '--fit', str(fitted), '-o', str(out), '--json']) == 0
    files = json.loads(capsys.readouterr().out)['files']
    page = _check_report(files, out, n_blocks=6)
    assert str(fitted) in page and 'chi2/dof' in page
    # parameters shown in the papers' units with their uncertainty: K0 about 12.3 kN/mm
    rows = _param_rows(page)
    element, k0, sigma, _, interval, unit, budget = rows['k0']
    assert element == 'fractional_zener' and unit == 'kN/mm'
    assert float(k0) == pytest.approx(12.29, rel=0.02)
    assert sigma.startswith('&plusmn;') and float(sigma[8:]) > 0 and interval.startswith('[')
    # the uncertainty budget: Type A from the data; this simulated load cell is declared exact (0 %)
    assert budget.startswith('Type A ') and 'load-cell gain 0' in budget, budget
    assert rows['x2'][5] == 'mm' and rows['f_fmax'][5] == 'kN' and rows['alpha'][5] == '-'
    assert 'class="box warnings"' in page or 'class="box ok"' in page


def test_report_from_a_model_file_with_a_cubic_spring(recording, tmp_path, capsys):
    from rubber_rig.cli.main import main
    model = tmp_path / 'cubic.yaml'
    model.write_text(CUBIC_MODEL)
    out = tmp_path / 'cubic'
    assert main(['report', str(recording), '--fit', str(model), '-o', str(out), '--json']) == 0
    files = json.loads(capsys.readouterr().out)['files']
    # R_K / R_E split seed 000's model only: left out, with a sentence saying so
    page = _check_report(files, out, n_blocks=6, figures=[f for f in FIGURES if f != 'ratios'])
    assert 'not fractional Zener + Berg, so the figure is left out' in page
    rows = _param_rows(page)
    assert set(rows) == {'k0', 'k_inf', 'tau', 'alpha', 'x2', 'f_fmax', 'k3', 'load_cell_delay'}
    assert rows['k0'][1:3] == ['12.29', '&plusmn;0.05'] and rows['k0'][5] == 'kN/mm'
    assert rows['k3'][1:3] == ['0.6', '&plusmn;0.2'] and rows['k3'][5] == 'kN/mm^3'
    assert rows['k0'][6] == ''          # a model file written without a budget shows none
    assert rows['k3'][4] == '[0.208, 0.992]'
    assert rows['load_cell_delay'][1:3] == ['0.1', '&plusmn;0.02'] and rows['load_cell_delay'][5] == 'ms'
    assert '<b>4.2</b>' in page                                   # chi2/dof of the fit
    box = page.split('class="box warnings"')[1].split('</div>')[0]
    assert 'misfit: chi2/dof = 4.2, the model misses something the data show' in box
    assert 'x2 and f_fmax are correlated' in page                 # the fit's notes
    assert '50 parameter sets drawn from independent normals' in page


def test_report_fits_when_no_parameters_are_given(recording, tmp_path, capsys):
    from rubber_rig.cli.main import main
    out = tmp_path / 'auto'
    assert main(['report', str(recording), '-o', str(out), '--method', 'harmonic', '--json']) == 0
    files = json.loads(capsys.readouterr().out)['files']
    assert files['html'].endswith('report.html')
    page = _check_report(files, out, n_blocks=6)
    assert 'fitted to this recording' in page and '&plusmn;' in page      # uncertainty shown


def test_report_with_a_shipped_parameter_set(recording, tmp_path, capsys):
    """The shipped swing_arm_joint.yaml (models library) is readable as a --fit file; --set picks the set."""
    from pathlib import Path

    import rubber_rig.models
    from rubber_rig.cli.main import main
    shipped = Path(rubber_rig.models.__file__).parent / 'data' / 'swing_arm_joint.yaml'
    out = tmp_path / 'shipped'
    assert main(['report', str(recording), '--fit', str(shipped), '--set', 'seed000_20C', '-o', str(out),
                 '--json']) == 0
    page = _check_report(json.loads(capsys.readouterr().out)['files'], out, n_blocks=6)
    assert 'no fit record' in page                               # a parameter set has no sigma or warnings
    # the true specimen reproduces the measured K_dyn within 1 % in every block (model run and first harmonic)
    table = page.split('<h2>Blocks</h2>')[1].split('</table>')[0]
    cells = [re.findall(r'<td>([-0-9.e+]+)</td>', row) for row in table.split('<tr>')[2:]]
    assert len(cells) == 6 and all(abs(float(c[7])) < 1.0 and abs(float(c[8])) < 1.0 for c in cells)
    assert main(['report', str(recording), '--fit', str(shipped), '--set', 'nope', '-o', str(out)]) == 2
    assert 'nope' in capsys.readouterr().err


def test_the_delay_interval_is_the_fits_own(tmp_path):
    from rubber_rig.fitting.modelfit import Z95
    from rubber_rig.fitting.report_model import read_model_file
    path = tmp_path / 'm.yaml'
    path.write_text(CUBIC_MODEL.replace('delay_sigma: 2.0e-5}',
                                        'delay_sigma: 2.0e-5, delay_interval_95: [5.84e-5, 1.416e-4]}'))
    assert read_model_file(path).results['load_cell_delay']['interval_95'] == [5.84e-5, 1.416e-4]   # +-t sigma
    path.write_text(CUBIC_MODEL)          # written before fits stored it: +-1.96 sigma
    assert read_model_file(path).results['load_cell_delay']['interval_95'] == pytest.approx(
        [1e-4 - Z95 * 2e-5, 1e-4 + Z95 * 2e-5], rel=1e-12)


def test_one_misfit_verdict_in_the_cli_the_json_the_model_file_and_the_report(recording, tmp_path, capsys):
    """Issue 38 item 8: the report's header, the CLI and the JSON state the same misfit figure and test."""
    import yaml

    from rubber_rig.cli.main import main
    fitted = tmp_path / 'fit.yaml'
    assert main(['fit', str(recording), '-o', '-', '--json', '--no-progress']) == 0
    data = json.loads(capsys.readouterr().out)
    assert main(['fit', str(recording), '-o', str(fitted), '--no-progress']) == 0
    text = capsys.readouterr().out
    summary = data['misfit_summary']
    ratio = data['misfit']['ratio']
    assert data['chi2_per_dof'] == ratio and data['fits'][0]['chi2_per_dof'] == ratio
    assert summary.startswith(f'chi2/dof = {ratio:.3g} ') and '(two-sided)' in summary
    assert summary in text                                       # the CLI prints the same sentence
    record = yaml.safe_load(fitted.read_text())['fit']
    assert record['chi2_per_dof'] == pytest.approx(ratio) and record['misfit_test']['summary'] == summary
    out = tmp_path / 'report'
    assert main(['report', str(recording), '--fit', str(fitted), '-o', str(out), '--json']) == 0
    capsys.readouterr()
    page = (out / 'report.html').read_text()
    box = page.split('<p>Fit:')[1].split('</p>')[0]
    assert f'<b>{ratio:.3g}</b>' in box and summary in box
