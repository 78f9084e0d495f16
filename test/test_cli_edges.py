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

"""CLI edge cases through the installed `rubber-rig` command: conflicting options are usage errors (exit 2,
both options named), unwritable outputs end in one line naming the path (exit 1, no traceback), and
`props` refuses out-of-range input with the option and the allowed range before doing any work."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.writer import Writer

RUBBER_RIG = Path(sys.executable).with_name('rubber-rig')
pytestmark = pytest.mark.skipif(not RUBBER_RIG.exists(), reason=f'{RUBBER_RIG} is not installed')


def cli(*args, prefix=(), timeout=120):
    return subprocess.run([*prefix, str(RUBBER_RIG), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


def assert_one_line_error(proc, code, *needles):
    err = proc.stderr.strip()
    assert proc.returncode == code, (proc.returncode, proc.stdout, proc.stderr)
    assert 'Traceback' not in proc.stderr, proc.stderr
    last = err.splitlines()[-1]
    for needle in needles:
        assert needle in last, (needle, err)
    return last


@pytest.fixture
def mcap_file(tmp_path):
    """A small complete MCAP file (recover copies any MCAP file)."""
    path = tmp_path / 'half.mcap'
    with open(path, 'wb') as f:
        w = Writer(f)
        w.start('ros2', 'test')
        schema = w.register_schema('std_msgs/msg/String', 'ros2msg', b'string data')
        channel = w.register_channel('/x', 'cdr', schema)
        for i in range(10):
            w.add_message(channel, i, b'\x00\x01\x00\x00\x02\x00\x00\x00a\x00', i, i)
        w.finish()
    return path


# ---- recover: conflicting options ------------------------------------------------------------------------

def test_recover_in_place_with_output_is_a_usage_error(mcap_file):
    before = mcap_file.read_bytes()
    out = mcap_file.with_name('other.mcap')
    proc = cli('recover', mcap_file, '--in-place', '-o', out)
    assert_one_line_error(proc, 2, '--in-place', '-o/--output')
    assert 'usage: rubber-rig recover' in proc.stderr
    assert mcap_file.read_bytes() == before and not out.exists()
    assert sorted(p.name for p in mcap_file.parent.iterdir()) == ['half.mcap']


@pytest.mark.parametrize('extra', [(), ('-o', 'other.mcap')])
def test_recover_no_backup_without_in_place_is_a_usage_error(mcap_file, extra):
    proc = cli('recover', mcap_file, '--no-backup', *extra)
    assert_one_line_error(proc, 2, '--no-backup', '--in-place')
    assert sorted(p.name for p in mcap_file.parent.iterdir()) == ['half.mcap']


def test_recover_in_place_no_backup_still_works(mcap_file):
    proc = cli('recover', mcap_file, '--in-place', '--no-backup')
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in mcap_file.parent.iterdir()) == ['half.mcap']


# ---- recover: unwritable outputs -------------------------------------------------------------------------

def _read_only_dir(tmp_path):
    """A directory this process cannot write, and the command prefix that makes it so.

    chmod 0o555 is enough for a normal user; root writes through permission bits, so then the directory
    is bind-mounted read-only in a private mount namespace of the command (a real EROFS)."""
    ro = tmp_path / 'ro'
    ro.mkdir()
    ro.chmod(0o555)
    try:
        (ro / 'probe').touch()
    except OSError:
        return ro, ()                                  # permission bits hold
    (ro / 'probe').unlink()
    ro.chmod(0o755)
    unshare = shutil.which('unshare')
    if unshare is None:
        pytest.skip('running as root (permission bits do not stop writes) and unshare(1) is missing')
    prefix = (unshare, '--mount', 'sh', '-c', 'mount --bind -o ro "$0" "$0" && exec "$@"', str(ro))
    probe = subprocess.run([*prefix, 'touch', str(ro / 'probe')], capture_output=True, text=True)
    if probe.returncode == 0 or 'Read-only file system' not in probe.stderr:
        (ro / 'probe').unlink(missing_ok=True)
        pytest.skip(f'cannot make a read-only directory here (root, private mount namespace refused: '
                    f'{probe.stderr.strip()!r})')
    return ro, prefix


def test_recover_onto_a_read_only_directory(tmp_path, mcap_file):
    ro, prefix = _read_only_dir(tmp_path)
    target = ro / 'out.mcap'
    try:
        proc = cli('recover', mcap_file, '-o', target, prefix=prefix)
        line = assert_one_line_error(proc, 1, str(target))
        assert line.startswith('rubber-rig recover: error: cannot write')
        assert len(proc.stderr.strip().splitlines()) == 1
        assert not target.exists()
    finally:
        ro.chmod(0o755)


def test_recover_in_place_in_a_read_only_directory_keeps_the_original(tmp_path, mcap_file):
    ro, prefix = _read_only_dir(tmp_path)
    ro.chmod(0o755)
    src = ro / 'rec.mcap'
    shutil.copy(mcap_file, src)
    before = src.read_bytes()
    if not prefix:
        ro.chmod(0o555)
    try:
        proc = cli('recover', src, '--in-place', prefix=prefix)
        assert_one_line_error(proc, 1, 'cannot write', str(ro))
    finally:
        ro.chmod(0o755)
    assert src.read_bytes() == before
    assert sorted(p.name for p in ro.iterdir()) == ['rec.mcap']


@pytest.mark.parametrize('where', ['parent_is_a_file', 'missing_directory'])
def test_recover_onto_an_impossible_path(tmp_path, mcap_file, where):
    plain = tmp_path / 'plain'
    plain.write_text('a regular file')
    target = plain / 'out.mcap' if where == 'parent_is_a_file' else tmp_path / 'nowhere' / 'out.mcap'
    proc = cli('recover', mcap_file, '-o', target)
    assert_one_line_error(proc, 1, f'cannot write {target}')
    assert len(proc.stderr.strip().splitlines()) == 1
    assert plain.read_text() == 'a regular file'


def test_recover_of_a_missing_input_is_bad_input(tmp_path):
    proc = cli('recover', tmp_path / 'none.mcap')
    assert_one_line_error(proc, 2, str(tmp_path / 'none.mcap'))


# ---- props: ranges and bounded cost ----------------------------------------------------------------------

@pytest.mark.parametrize('args,needles', [
    (('-a', '1e300mm'), ('--amplitude', '1e300mm', '1e-09 .. 1 m')),
    (('-a', '0'), ('--amplitude', '1e-09 .. 1 m')),
    (('-a', '1.5m'), ('--amplitude', '1.5m', '1e-09 .. 1 m')),
    (('-f', '1e300'), ('--frequency', '1e-06 .. 1e+06 Hz')),
    (('--method', 'time', '-f', '1e-9Hz'), ('--frequency', '1e-9Hz', '1e-06 .. 1e+06 Hz')),
    (('--method', 'time', '-f', '0.001Hz'), ('--frequency 0.001 Hz', 'samples', '--frequency >= 0.01 Hz')),
    (('--method', 'time', '-f', '1', '--rate', '0'), ('--rate', '1 .. 1e+06 Hz')),
    (('--method', 'time', '-f', '1', '--cycles', '1000000000'), ('--cycles', '3 .. 10000')),
    (('--frequency-grid', '1Hz', '10Hz', '1000000000'), ('--frequency-grid', '1 .. 10000')),
    (('--frequency-grid', '0', '10Hz', '5'), ('--frequency-grid', '1e-06 .. 1e+06 Hz')),
])
def test_props_refuses_out_of_range_input_quickly(args, needles):
    proc = cli('props', *args, timeout=60)
    assert_one_line_error(proc, 2, 'rubber-rig props: error:', *needles)
    assert proc.stdout == ''


def test_props_time_method_total_cost_is_bounded():
    proc = cli('props', '--method', 'time', '-f', *(['0.011Hz'] * 12), '-a', '1mm', timeout=60)
    assert_one_line_error(proc, 2, '--method time', 'samples', 'in total')


def test_props_non_finite_closed_forms_are_shown_not_crashed():
    """Within the physical range the closed forms of a parameter set can still lose precision (Berg's
    element far beyond its x2): the table shows '-', JSON null, and stderr says where."""
    proc = cli('props', '--kdyn', 'eq24', '-p', 'seed000_20C', '-f', '1Hz', '-a', '10cm', '1mm')
    assert proc.returncode == 0 and 'Traceback' not in proc.stderr, proc.stderr
    rows = proc.stdout.strip().splitlines()[2:]
    assert len(rows) == 2
    assert rows[0].split()[2] == '-' and rows[1].split()[2] != '-'
    assert 'warning' in proc.stderr and '100 mm' in proc.stderr
    js = cli('props', '--kdyn', 'eq24', '-p', 'seed000_20C', '-f', '1Hz', '-a', '10cm', '--json')
    assert js.returncode == 0 and '"k_dyn": null' in js.stdout


def test_discovery_range_default_reaches_the_sub_command(tmp_path):
    """The CLI defaults ROS_AUTOMATIC_DISCOVERY_RANGE to LOCALHOST for every sub-command (bench's node
    processes inherit it) and leaves a user's choice alone."""
    from rubber_rig.cli.main import keep_discovery_local
    env = {}
    assert keep_discovery_local(env) == 'LOCALHOST' and env == {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    env = {'ROS_AUTOMATIC_DISCOVERY_RANGE': ''}
    assert keep_discovery_local(env) == 'LOCALHOST'
    for chosen in ('SUBNET', 'OFF', 'SYSTEM_DEFAULT'):
        env = {'ROS_AUTOMATIC_DISCOVERY_RANGE': chosen}
        assert keep_discovery_local(env) == chosen
    code = ('import os, sys; from rubber_rig.cli import main as m; '
            'm.COMMANDS = {"probe": "probe_cmd"}; sys.exit(m.main(["probe"]))')
    (tmp_path / 'probe_cmd.py').write_text(
        '"""probe"""\nimport os\n\ndef add_arguments(p):\n    pass\n\n'
        'def run(args):\n    print(os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE"))\n    return 0\n')
    base = {k: v for k, v in os.environ.items() if k != 'ROS_AUTOMATIC_DISCOVERY_RANGE'}
    base['PYTHONPATH'] = os.pathsep.join([str(tmp_path), base.get('PYTHONPATH', '')])
    for extra, expected in (({}, 'LOCALHOST'), ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}, 'SUBNET')):
        out = subprocess.run([sys.executable, '-c', code], env={**base, **extra}, capture_output=True,
                             text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert out.stdout.strip() == expected


def test_recover_and_info_of_a_truncated_file_say_the_tail_is_unaccounted(tmp_path, mcap_file):
    data = mcap_file.read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:len(data) * 2 // 3])       # writer killed: no summary, no footer
    info = cli('info', cut)
    assert info.returncode == 0 and 'Traceback' not in info.stderr, info.stderr
    assert 'NOT CLOSED' in info.stdout and 'unaccounted' in info.stdout
    proc = cli('recover', cut, '-o', tmp_path / 'fixed.mcap')
    assert proc.returncode == 0, proc.stderr
    assert 'was truncated' in proc.stdout and 'unaccounted' in proc.stdout
