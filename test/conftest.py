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

"""Shared pytest set-up: the ROS 2 middleware is real Fast DDS from the ros-jazzy-* wheels."""
import os

os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
# One BLAS thread (before numpy is imported): on two cores OpenBLAS's threads cost the fits 2-3x the CPU for the same
# numbers to the last digit (docs/benchmarks/identification_notes.md), and they take the cores the node processes
# of the end-to-end tests need. A caller's choice is kept.
for _threads in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_threads, '1')
# Keep test traffic on this machine and away from other ROS graphs on the network, unless the caller chose
# a range (README "Networking"); an empty value counts as unset, as in `rubber-rig`. Set here, at import,
# before any test module imports rclpy; node processes the tests start inherit it.
if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

# The rig key of this test session (README "Who may move the rig"): a fresh one in a private directory, never the
# user's; the node processes and the clients (the test operator, rubber-rig bench) the tests start inherit its path.
# Set at import, before any node starts; a caller's RUBBER_RIG_KEY_FILE is kept.
if not os.environ.get('RUBBER_RIG_KEY_FILE'):
    import atexit  # noqa: E402
    import shutil  # noqa: E402
    import tempfile  # noqa: E402

    from rubber_rig.security import init_key  # noqa: E402
    _key_dir = tempfile.mkdtemp(prefix='rubber_rig_test_key_')
    os.environ['RUBBER_RIG_KEY_FILE'] = str(init_key(os.path.join(_key_dir, 'rig.key')))
    atexit.register(shutil.rmtree, _key_dir, True)

import pytest  # noqa: E402


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Keep each phase's report on the test item (rep_setup, rep_call): fixtures read it at teardown to add
    diagnostics to a failure (the fault matrix prints its node logs)."""
    outcome = yield
    setattr(item, f'rep_{call.when}', outcome.get_result())


def _group(item) -> str:
    """The pytest-xdist group of a test: 'end_to_end' for those that run processes on the wall clock (markers ros
    and slow: node processes on a DDS domain, a simulator process on a bus), else its module."""
    return 'end_to_end' if item.get_closest_marker('ros') or item.get_closest_marker('slow') else item.module.__name__


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """make test runs on two pytest-xdist workers (--dist loadgroup): the tests of one module stay on one worker
    (module fixtures are set up once), and the end-to-end tests all run on one worker, one after the other, so two of
    them never share the DDS domains or the cores; the logic tests on simulated time fill the other worker.

    pytest-xdist 3.8 marks a test's group by appending '@group' to its node id, which it does by setting the
    attribute pytest 8 kept the id in; pytest 9 keeps it elsewhere, so the groups would be silently ignored (and two
    suites of nodes met on one DDS domain). The id is set here as xdist would, on the worker (option loadgroup).
    """
    if not getattr(config.option, 'loadgroup', False):
        return
    from _pytest.nodeid import NodeId
    for item in items:
        if '@' not in item.nodeid.rsplit('::', 1)[-1]:
            item._id = NodeId.parse(f'{item.nodeid}@{_group(item)}')
