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

"""Foundation checks: the ament packages are well-formed and every declared executable exists."""
import importlib
import pathlib

from catkin_pkg.package import parse_package

from support.package import console_scripts_specs

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_rubber_rig_package_xml_declares_jazzy_dependencies():
    pkg = parse_package(str(ROOT / 'package.xml'))
    assert pkg.package_format == 3 and pkg.name == 'rubber_rig'
    deps = {d.name for d in pkg.build_depends + pkg.exec_depends}
    for key in ('rclpy', 'std_msgs', 'builtin_interfaces', 'diagnostic_msgs', 'std_srvs', 'lifecycle_msgs',
                'msg_defs', 'python3-numpy', 'python3-scipy', 'python3-yaml'):
        assert key in deps, key
    assert pkg.get_build_type() == 'ament_python'


def test_msg_defs_is_an_interface_package():
    pkg = parse_package(str(ROOT / 'msg_defs' / 'package.xml'))
    assert pkg.package_format == 3 and pkg.get_build_type() == 'ament_cmake'
    assert 'rosidl_interface_packages' in [g.name for g in pkg.member_of_groups]
    cmake = (ROOT / 'msg_defs' / 'CMakeLists.txt').read_text()
    for f in sorted((ROOT / 'msg_defs').glob('*/*.*')):
        if f.suffix in ('.msg', '.srv', '.action'):
            assert f'"{f.parent.name}/{f.name}"' in cmake, f'{f.name} is not listed in rosidl_generate_interfaces'


def test_every_console_script_resolves_to_a_callable():
    scripts = console_scripts_specs()
    names = {s.split('=')[0].strip() for s in scripts}
    assert {'rubber-rig', 'rig_driver', 'excitation', 'element_model', 'recorder'} <= names
    for spec in scripts:
        target = spec.split('=')[1].strip()
        module_name, func = target.split(':')
        assert callable(getattr(importlib.import_module(module_name), func)), spec


def test_ament_index_marker_and_data_files():
    assert (ROOT / 'resource' / 'rubber_rig').is_file()
    setup_text = (ROOT / 'setup.py').read_text()
    for needle in ("'share/ament_index/resource_index/packages'", "'/launch'", "'/config'"):
        assert needle in setup_text


def test_the_version_is_written_once_in_package_xml(capsys):
    """package.xml states the version; setup.py, rubber_rig.__version__, MCAP metadata and --version follow it,
    and the interface package is released with it."""
    import pytest

    import rubber_rig
    from rubber_rig.cli.main import main
    version = parse_package(str(ROOT / 'package.xml')).version
    assert parse_package(str(ROOT / 'msg_defs' / 'package.xml')).version == version
    assert rubber_rig.__version__.split('+')[0] == version
    import re
    assert not re.search(r'version\s*=\s*[\'"]', (ROOT / 'setup.py').read_text()), 'setup.py writes a version'
    with pytest.raises(SystemExit):
        main(['--version'])
    assert capsys.readouterr().out.strip() == f'rubber-rig {rubber_rig.__version__}'


def test_shipped_config_is_found_in_a_checkout_and_in_an_install_prefix(tmp_path, monkeypatch):
    """A colcon install puts config/ in <prefix>/share/rubber_rig/config (found through AMENT_PREFIX_PATH)."""
    import pytest

    from rubber_rig.paths import config_dirs, config_file, find_config
    assert find_config('rig_sim.yaml') == ROOT / 'config' / 'rig_sim.yaml'
    assert config_file('foxglove_layout.json') == ROOT / 'config' / 'foxglove_layout.json'
    share = tmp_path / 'install' / 'share' / 'rubber_rig' / 'config'
    share.mkdir(parents=True)
    (share / 'site_rig.yaml').write_text('rig_driver: {}\n')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path / 'install'))
    assert share in config_dirs() and config_dirs()[0] == ROOT / 'config'
    assert find_config('site_rig.yaml') == share / 'site_rig.yaml'
    with pytest.raises(FileNotFoundError, match=str(share)):
        find_config('no_such_rig.yaml')
