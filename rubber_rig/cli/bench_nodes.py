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

"""How ``rubber-rig bench`` starts the suite's nodes, and what it knows of them before they answer.

:class:`NodeProcesses` (the default): each node in a process of its own, started and stopped the way ``ros2 launch
rubber_rig rig_sim.launch.py`` does (rubber_rig.cli.processes: same executables, same parameter file, overrides
in a second file, SIGINT to stop), and the paced simulated rig in a process of its own on a bus that crosses
processes (python-can udp_multicast over loopback). No interpreter lock is shared: a busy model does not delay the
driver. :class:`InProcessNodes` (``--in-process``): the same node classes as threads of this process, one
SingleThreadedExecutor each (rubber_rig.launching.inprocess), the simulated rig a thread of rig_driver.

Either way the bench talks to the nodes only through their ROS interfaces (the monitor node in this process).
:func:`suite_facts` reads what the summary states about the rig (rate, batch, specimen) from the same parameter
file and overrides the nodes get.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import yaml

from rubber_rig.cli.main import CommandError
from rubber_rig.cli.processes import SuiteProcesses, separate_sim_rig

STOP_ORDER = ('rig_driver', 'excitation', 'element_model', 'foxglove_view', 'recorder')   # the rig to rest first
LOG_LINES = 5       # lines of a dead node's log shown with the error


class InProcessNodes:
    """The nodes as threads of this process (``--in-process``), in ``launcher`` (an InProcessLauncher)."""

    description = 'one SingleThreadedExecutor thread each, in this process; simulated rig: a thread of rig_driver'

    def __init__(self, launcher):
        self.launcher = launcher

    def driver_overrides(self, paced: bool) -> dict:
        return {}

    def start(self, node: str, overrides: dict) -> None:
        from rubber_rig.nodes.element_model_node import ElementModelNode
        from rubber_rig.nodes.excitation_node import ExcitationNode
        from rubber_rig.nodes.foxglove_view_node import FoxgloveViewNode
        from rubber_rig.nodes.recorder_node import RecorderNode
        from rubber_rig.nodes.rig_driver_node import RigDriverNode
        classes = {'rig_driver': RigDriverNode, 'excitation': ExcitationNode, 'element_model': ElementModelNode,
                   'recorder': RecorderNode, 'foxglove_view': FoxgloveViewNode}
        self.launcher.start(classes[node], overrides)

    def check(self) -> None:
        self.launcher.check()

    def pids(self) -> dict[str, int]:
        return {}          # every node is this process

    def close(self) -> None:
        pass               # the launcher shuts the nodes down with its context


class NodeProcesses:
    """Each node in a process of its own, as ``ros2 launch`` starts them; their logs in ``log_dir``."""

    def __init__(self, params_file, namespace: str, domain_id: int):
        self.domain_id, self.namespace = domain_id, namespace
        self.log_dir = Path(tempfile.mkdtemp(prefix='rubber_rig_bench_'))
        self.procs = SuiteProcesses(params_file, '/' + namespace.strip('/'), domain_id, self.log_dir)
        self.started: list[str] = []

    @property
    def description(self) -> str:
        return f'one process each (logs: {self.log_dir})'

    def driver_overrides(self, paced: bool) -> dict:
        """A paced simulated rig runs in a process of its own on udp_multicast; unpaced (--fast) it has no clock of
        its own (rig_driver's reads pump it), so it stays a part of rig_driver's process.
        """
        return separate_sim_rig(self.domain_id, self.namespace) if paced else {}

    def start(self, node: str, overrides: dict) -> None:
        """Start one node process and wait for its ready line; CommandError with its log if it ends instead."""
        from rubber_rig.cli.bench_session import CONNECT_TIMEOUT
        self.procs.start(node, overrides)
        self.started.append(node)
        if not self.procs.wait_started(node, CONNECT_TIMEOUT):
            self.check()
            raise CommandError(f'{node} did not say ready within {CONNECT_TIMEOUT:.0f} s; its log: '
                               f'{self.log_dir / (node + ".log")}')

    def check(self) -> None:
        """CommandError naming a node process that ended, with the end of its log."""
        for node in self.started:
            p = self.procs.procs.get(node)
            if p is not None and p.poll() is not None:
                tail = '\n    '.join(self.procs.log(node).strip().splitlines()[-LOG_LINES:])
                raise CommandError(f'{node} ended (exit status {p.returncode}); the end of its log '
                                   f'{self.log_dir / (node + ".log")}:\n    {tail}')

    def pids(self) -> dict[str, int]:
        return self.procs.pids()

    def close(self) -> None:
        """SIGINT to each node as launch does, the rig first (it ramps to rest); SIGKILL after 10 s."""
        for node in sorted(self.procs.procs, key=lambda n: STOP_ORDER.index(n) if n in STOP_ORDER else 0):
            self.procs.stop(node)


# -- what the parameter file says ---------------------------------------------------------------------------------
@dataclass
class SuiteFacts:
    """The rig and node settings the bench reports, from the parameter file and the command line's overrides."""

    backend: str
    sample_rate: float          # [Hz]
    paced: bool
    specimen: str               # the simulated specimen's parameter set (or its temperature)
    batch_size: int             # samples per RigSampleBatch
    max_batch_delay: float      # [s]
    hold_timeout: float         # [s] the excitation's
    model_source: str           # element_model's parameter source


def node_parameters(params_file, node: str) -> dict:
    """{dotted name: value} of ``node``'s section(s) of a ros2 parameter file ('/**/node', '/**' or 'node')."""
    doc = yaml.safe_load(Path(params_file).read_text()) or {}
    out: dict = {}

    def flatten(prefix: str, value) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                flatten(f'{prefix}.{k}' if prefix else str(k), v)
        else:
            out[prefix] = value
    for key, section in doc.items():
        if str(key).rstrip('/').split('/')[-1] in (node, '**') and isinstance(section, dict):
            flatten('', section.get('ros__parameters', {}))
    return out


def suite_facts(params_file, driver_overrides: dict, excitation_overrides: dict) -> SuiteFacts:
    from rubber_rig.nodes.rig_driver_node import BATCH_PERIOD
    drv = dict(node_parameters(params_file, 'rig_driver'), **driver_overrides)
    exc = dict(node_parameters(params_file, 'excitation'), **excitation_overrides)
    model = node_parameters(params_file, 'element_model')
    rate = float(drv.get('sample_rate', 1000.0))
    specimen = drv.get('sim.specimen.parameter_set') or f"at {drv.get('sim.specimen.temperature', 20.0):g} degC"
    return SuiteFacts(backend=str(drv.get('backend', 'sim')), sample_rate=rate, paced=bool(drv.get('paced', True)),
                      specimen=str(specimen),
                      batch_size=int(drv.get('batch_size', 0)) or max(1, round(BATCH_PERIOD * rate)),
                      max_batch_delay=float(drv.get('max_batch_delay', 0.1)),
                      hold_timeout=float(exc.get('hold_timeout', 600.0)),
                      model_source=str(model.get('source', 'parameter_set')))


def domain_of(domain_id: int | None) -> int:
    """The ROS domain the nodes run on: --domain-id, else $ROS_DOMAIN_ID, else 0."""
    if domain_id is not None:
        return int(domain_id)
    try:
        return int(os.environ.get('ROS_DOMAIN_ID', '0') or 0)
    except ValueError:
        raise CommandError(f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']!r} is not a number") from None
