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

"""The node suite in one process (real rclpy + Fast DDS): start it, run a program, read batches by sequence."""
import os

import numpy as np

from rubber_rig.launching.inprocess import InProcessLauncher
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes.element_model_node import ElementModelNode
from rubber_rig.nodes.excitation_node import ExcitationNode
from rubber_rig.nodes.monitor import SuiteMonitor
from rubber_rig.nodes.recorder_node import RecorderNode
from rubber_rig.nodes.rig_driver_node import RigDriverNode

CONFIG = os.path.join(os.path.dirname(__file__), '..', '..', 'config', 'rig_sim.yaml')
RATE = 1000.0
PROGRAM = """
name: node_test
defaults: {taper_cycles: 1, mean: 0.0}
blocks:
  - {name: a, waveform: sine, frequency: 5 Hz, amplitude: 0.5 mm, cycles: 8}
  - {name: b, waveform: sine, frequency: 2 Hz, amplitude: 1 mm, cycles: 6}
"""
FORCE_NOISE, DISP_NOISE = 2.0, 0.2e-6


def domain_id() -> int:
    """A DDS domain of our own: other test runs on this machine must not be seen (or see us)."""
    return 100 + os.getpid() % 100


def start_suite(tmp_path, driver=None, excitation=None, recorder=True):
    launcher = InProcessLauncher([CONFIG], domain_id=domain_id())
    nodes = {}
    if recorder:
        nodes['recorder'] = launcher.start(RecorderNode, {'output_dir': str(tmp_path), 'discovery_period': 0.2})
    nodes['model'] = launcher.start(ElementModelNode)
    nodes['excitation'] = launcher.start(ExcitationNode, excitation or {})
    nodes['driver'] = launcher.start(RigDriverNode, dict({'paced': False}, **(driver or {})))
    nodes['monitor'] = launcher.spin(SuiteMonitor(context=launcher.context, keep_messages=True))
    mon = nodes['monitor']
    wanted = ('samples', 'prediction', 'setpoints', 'cycle_metrics') if recorder else ()
    assert launcher.wait_for(lambda: mon.status is not None and nodes['excitation'].rig_ready() == ''
                             and mon.action.server_is_ready() and mon.recorder_subscribed(*wanted), 30.0), \
        'suite did not connect'
    return launcher, nodes


def run_program(launcher, mon, text, amplitude_control=False, timeout=90.0):
    future = mon.send_program(text, amplitude_control=amplitude_control)
    assert launcher.wait_for(future.done, 30.0)
    handle = future.result()
    assert handle.accepted
    result = handle.get_result_async()
    assert launcher.wait_for(result.done, timeout), 'program did not finish'
    return result.result().result


def by_sequence(batches, field):
    """Concatenate a field of batch messages into {sequence: value} arrays (seq array, values array)."""
    seq = np.concatenate([np.arange(m.first_sequence, m.first_sequence + len(m.displacement)) for m in batches])
    val = np.concatenate([conv.as_array(getattr(m, field)) for m in batches])
    return seq, val
