"""Shared pytest set-up: the ROS 2 middleware is real Fast DDS from the ros-jazzy-* wheels."""
import os

os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
# Keep test traffic on this machine and away from other ROS graphs on the network, unless the caller chose
# a range (README "Networking"); an empty value counts as unset, as in `rubber-rig`. Set here, at import,
# before any test module imports rclpy; node processes the tests start inherit it.
if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'


import pytest  # noqa: E402


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Keep each phase's report on the test item (rep_setup, rep_call): fixtures read it at teardown to add
    diagnostics to a failure (the fault matrix prints its node logs)."""
    outcome = yield
    setattr(item, f'rep_{call.when}', outcome.get_result())
