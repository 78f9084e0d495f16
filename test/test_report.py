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

from rubber_rig.fitting.report import FIGURES

PNG = b'\x89PNG\r\n\x1a\n'
PROGRAM = {'name': 'report_test', 'defaults': {'taper_cycles': 1, 'cycles': 6, 'mean': 0.0},
           'blocks': [{'waveform': 'sine', 'amplitude': ['0.5 mm', '1 mm'], 'frequency': ['1 Hz', '4 Hz', '12 Hz']}]}


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    from rubber_rig.fitting.simulate import simulated_recording
    return simulated_recording(tmp_path_factory.mktemp('rep') / 'run_20C.mcap', PROGRAM, 'seed000_20C', 20.0,
                               force_noise=10.0)


def _check_report(files, outdir, n_blocks):
    assert set(files) == set(FIGURES) | {'html'}
    for name in FIGURES:
        path = outdir / f'{name}.png'
        assert path.exists() and path.stat().st_size > 5000, name
        assert path.read_bytes()[:8] == PNG
    page = (outdir / 'report.html').read_text()
    images = re.findall(r'<img alt="(\w+)" src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert [a for a, _ in images] == list(FIGURES)
    for alt, b64 in images:    # the embedded images are the PNG files themselves
        assert base64.b64decode(b64) == (outdir / f'{alt}.png').read_bytes()
    assert 'src="http' not in page and '<link' not in page      # self-contained
    # one row per analysed block in the block table (header row + blocks)
    table = page.split('<h2>Blocks</h2>')[1].split('</table>')[0]
    assert table.count('<tr>') == n_blocks + 1
    return page


def test_report_with_a_fitted_parameter_file(recording, tmp_path, capsys):
    from rubber_rig.cli.main import main
    params = tmp_path / 'params.yaml'
    assert main(['fit', str(recording), '-o', str(params), '--method', 'harmonic', '--no-progress']) == 0
    capsys.readouterr()
    out = tmp_path / 'report'
    assert main(['report', str(recording), '--fit', str(params), '-o', str(out), '--json']) == 0
    files = json.loads(capsys.readouterr().out)['files']
    page = _check_report(files, out, n_blocks=6)
    assert 'set fit_20C' in page
    # parameters shown in the papers' units: K0 about 12.3 kN/mm
    row = page.split('<h2>Model parameters')[1].split('</table>')[0]
    k0 = float(re.findall(r'<td>([-0-9.e+]+)</td>', row)[0])
    assert k0 == pytest.approx(12.29, rel=0.02)


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
    # the true specimen reproduces the measured K_dyn within 1 % in every block
    errors = [float(e) for e in re.findall(r'<td>([-0-9.]+)</td><td>[-0-9.]+</td><td>[-0-9.]+</td><td>[-0-9.e+]+</td>'
                                           r'<td>[-0-9.e+]+</td><td>[-0-9.e+]+</td><td>[-0-9.e+]+</td></tr>', page)]
    assert len(errors) == 6 and max(abs(e) for e in errors) < 1.0
    assert main(['report', str(recording), '--fit', str(shipped), '--set', 'nope', '-o', str(out)]) == 2
    assert 'nope' in capsys.readouterr().err
