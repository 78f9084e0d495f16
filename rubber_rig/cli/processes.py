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

"""The suite as separate processes, the way ``ros2 launch`` starts it. ``rubber-rig bench`` runs its main job
this way; the fault-matrix tests and the benchmarks drive it from outside (rubber_rig.testing.operator).

Every node runs ``python -m rubber_rig.nodes.<node>_node --ros-args -r __ns:=<ns> --params-file <file> [--params-file
<overrides>]`` with the environment of a launch file (RMW, domain, LOCALHOST discovery unless set), its
output in ``<log_dir>/<node>.log``. Waits are bounded waits on conditions, never fixed sleeps.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import yaml

from rubber_rig.cpu import child_pids

NODES = ('rig_driver', 'excitation', 'element_model', 'recorder')


def separate_sim_rig(domain_id: int, namespace: str = '') -> dict:
    """rig_driver parameters for the simulated rig in a process of its own (spawn_sim), on python-can's
    udp_multicast bus over loopback: the bus that crosses processes (the virtual bus lives in one process).

    The multicast group and port follow from the ROS domain and namespace, so two suites on one machine (on
    different domains or namespaces) do not hear each other's frames. The frames cross at once: no CAN bit timing
    or bus load on this bus (the in-process simulated bus has them).
    """
    key = (int(domain_id) * 131 + sum(namespace.encode())) % 4000
    return {'backend': 'udp_multicast', 'spawn_sim': True, 'can.channel': f'239.74.{165 + key // 250}.{1 + key % 250}',
            'can.bus_options': json.dumps({'port': 46000 + key})}


def _end_orphans(pids: list[int], timeout: float = 5.0) -> None:
    """SIGTERM, then SIGKILL after `timeout` s, to the processes a node had started that outlived it (a node
    stopped while it was still starting never closes what it opened, e.g. a spawned simulated rig).
    """
    alive = [pid for pid in pids if _signal(pid, signal.SIGTERM)]
    deadline = time.monotonic() + timeout
    while alive and time.monotonic() < deadline:
        time.sleep(0.05)
        alive = [pid for pid in alive if _signal(pid, 0)]
    for pid in alive:
        _signal(pid, signal.SIGKILL)


def _signal(pid: int, sig: int) -> bool:
    """Send `sig` to `pid` (0: only ask whether it exists); False when it is gone (or is not ours)."""
    try:
        os.kill(pid, sig)
    except (ProcessLookupError, PermissionError):
        return False
    return True


NICE_NODES = ('rig_driver', 'excitation')   # the nodes that set their own niceness (parameter nice)


class SuiteProcesses:
    """Start, kill and restart the suite's node processes in namespace `namespace` on DDS domain `domain_id`.

    params_file: the shared ros2 parameter file (config/rig_sim.yaml); overrides: {node: {param: value}}
    written to a second parameter file per node (the later file wins, as in launch_ros).
    """

    def __init__(self, params_file, namespace: str, domain_id: int, log_dir, overrides: dict | None = None,
                 niceness: int = 0):
        self.params_file, self.namespace, self.domain_id = str(params_file), namespace, int(domain_id)
        # > 0: these processes yield the CPU to the rest (a second station that would run on its own computer
        # must not starve this machine's suite when both share two cores in a test)
        self.niceness = int(niceness)
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.overrides = {k: dict(v) for k, v in (overrides or {}).items()}
        self.procs: dict[str, subprocess.Popen] = {}
        self._logs = {}
        self.extra_args: dict[str, list[str]] = {}   # more --ros-args per node (remappings)
        self.prefix: dict[str, list[str]] = {}       # a command to run a node under (ip netns exec HOST: another host)
        # the node processes' working directory (None: this one's). `python -m` puts it first on sys.path, before
        # PYTHONPATH: nodes of another checkout (bench_suite --nodes-from) must run in that checkout
        self.cwd = None
        self._log_offset = {}
        self.env = dict(os.environ, ROS_DOMAIN_ID=str(self.domain_id), PYTHONUNBUFFERED='1')
        self.env.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
        if not self.env.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):
            self.env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

    def command(self, node: str, overrides: dict | None = None) -> list[str]:
        cmd = [*self.prefix.get(node, []), sys.executable, '-m', f'rubber_rig.nodes.{node}_node', '--ros-args',
               '-r', f'__ns:={self.namespace}', '--params-file', self.params_file]
        cmd += self.extra_args.get(node, [])
        params = dict(self.overrides.get(node, {}), **(overrides or {}))
        if self.niceness > 0 and node in NICE_NODES:
            params.setdefault('nice', self.niceness)    # else its parameter file's -10/-5 would undo the niceness
        if params:
            path = self.log_dir / f'{node}.overrides.yaml'
            path.write_text(yaml.safe_dump({'/**': {'ros__parameters': params}}))
            cmd += ['--params-file', str(path)]
        return cmd

    def start(self, node: str, overrides: dict | None = None) -> subprocess.Popen:
        """Start (or restart) one node process (wait_started() waits for it to say it is ready)."""
        self.stop(node)
        log = open(self.log_dir / f'{node}.log', 'ab')
        self._log_offset[node] = log.tell()
        self._logs[node] = log
        nice = (lambda: os.nice(self.niceness)) if self.niceness > 0 else None
        self.procs[node] = subprocess.Popen(self.command(node, overrides), env=self.env, stdout=log,
                                            stderr=subprocess.STDOUT, start_new_session=True, preexec_fn=nice,
                                            cwd=self.cwd)
        return self.procs[node]

    def start_all(self, nodes=NODES):
        for node in nodes:
            self.start(node)

    def wait_started(self, node: str, timeout: float = 30.0) -> bool:
        """Wait until the process started last for `node` logged its 'ready' line (spin_node logs it once the
        node and its interfaces exist). False if it did not within `timeout` s or the process ended.
        """
        path, offset = self.log_dir / f'{node}.log', self._log_offset.get(node, 0)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with open(path, 'rb') as f:
                f.seek(offset)
                if b']: ready (pid ' in f.read():
                    return True
            if not self.alive(node):
                return False
            time.sleep(0.02)
        return False

    def kill(self, node: str, sig: int = signal.SIGKILL):
        """Send `sig` to a node process and wait for it to end (SIGKILL: no clean-up at all)."""
        p = self.procs.get(node)
        if p is not None and p.poll() is None:
            p.send_signal(sig)
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=5)

    def stop(self, node: str, timeout: float = 10.0) -> int | None:
        """SIGINT (as Ctrl-C / launch shutdown) and wait; SIGKILL after `timeout`. Returns the exit code."""
        p = self.procs.pop(node, None)
        if p is None:
            return None
        children = child_pids(p.pid)      # e.g. the simulated rig rig_driver started (spawn_sim)
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
            try:
                p.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=5)
        _end_orphans(children)
        log = self._logs.pop(node, None)
        if log is not None:
            log.close()
        return p.returncode

    def alive(self, node: str) -> bool:
        p = self.procs.get(node)
        return p is not None and p.poll() is None

    def log(self, node: str) -> str:
        path = self.log_dir / f'{node}.log'
        return path.read_text(errors='replace') if path.exists() else ''

    def pids(self) -> dict[str, int]:
        """{node: process id} of the node processes running now."""
        return {node: p.pid for node, p in self.procs.items() if p.poll() is None}

    def stop_all(self):
        for node in list(self.procs):
            self.stop(node)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop_all()
