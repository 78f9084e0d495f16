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
"""Waiting for something to happen: poll a condition with a deadline instead of sleeping a fixed time.

A fixed delay is either too short on a loaded machine (a flaky test) or longer than needed everywhere else;
a deadline on a condition is as short as the machine allows and, when the thing never happens, says what.
"""
import time


def poll_until(condition, timeout, *, step=None, period=0.01):
    """Evaluate ``condition()`` until it is truthy or ``timeout`` seconds have passed; return its last value.

    ``step()`` runs between two evaluations (e.g. one ``executor.spin_once`` for a test that spins its own
    nodes); without it the poll pauses ``period`` seconds, for nodes that spin in threads of their own.
    """
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value or time.monotonic() >= deadline:
            return value
        if step is not None:
            step()
        else:
            time.sleep(period)  # the poll period, not a delay waited for its own sake


def wait_for(condition, timeout, what, *, step=None, period=0.01):
    """Wait until ``condition()`` is truthy and return its value; fail naming ``what`` did not happen in time.

    ``what`` completes 'timed out after N s waiting for ...', e.g. 'the recorder to subscribe to samples'.
    """
    value = poll_until(condition, timeout, step=step, period=period)
    if not value:
        raise AssertionError(f'timed out after {timeout:g} s waiting for {what}')
    return value
