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

"""`rubber-rig conformance --sim` run after run on this host, and what each timing requirement got: does a busy
computer fail the simulator for the host's delays (issue 36)? Each run is the system tier's: the simulator in a
process of its own over udp_multicast, in a private network namespace (nothing leaves the machine).

    .venv/bin/python benchmarks/busy_load.py --loops 2 -- .venv/bin/python benchmarks/bench_conformance_load.py
    .venv/bin/python benchmarks/bench_conformance_load.py --runs 5 --defect heartbeat_80ms     # on a quiet host

Prints per run the exit status (0 pass, 1 fail, 4 incomplete: not judged for this host's lateness), the load
average and the host-timing fact of the report, then per timing requirement how many runs passed, failed and were
not judged. Needs unshare and ip (root or unprivileged user namespaces).
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
import argparse
import collections
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

TIMING = ('CTRL-HB-1', 'CTRL-HB-2', 'CTRL-ST-1', 'CTRL-ST-2', 'CTRL-ST-4', 'CTRL-TEMP-1', 'CTRL-ID-2', 'CTRL-FB-1',
          'CTRL-FB-2', 'CTRL-SEQ-1', 'CTRL-STREAM-4', 'CTRL-WD-1')
NETNS_SETUP = 'ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec "$@"'
ARGS = ('--sim', '--power-up', '--envelope', '1mm', '--reference-spring', '10kN/mm±1%', '--ambient', '20degC±5K')


def verdicts(junit) -> dict:
    """Requirement id -> ('pass' | 'FAIL' | 'not judged' (this host was late) | 'not tested', the message) from a
    JUnit report.
    """
    out = {}
    for case in ET.parse(junit).getroot().iter('testcase'):
        skipped, failure = case.find('skipped'), case.find('failure')
        message = (failure if failure is not None else skipped).get('message', '') \
            if failure is not None or skipped is not None else ''
        out[case.get('name')] = ('FAIL' if failure is not None else
                                 'not judged' if skipped is not None and 'this host was late' in message else
                                 'not tested' if skipped is not None else 'pass', message)
    return out


def one_run(extra: list) -> tuple:
    """(exit status, verdicts, host-timing fact) of one conformance run in a private network namespace."""
    prefix = ['unshare', '--net'] if os.geteuid() == 0 else ['unshare', '--user', '--map-root-user', '--net']
    with tempfile.TemporaryDirectory(prefix='bench_conformance_') as tmp:
        junit = os.path.join(tmp, 'report.xml')
        proc = subprocess.run([*prefix, 'sh', '-c', NETNS_SETUP, 'sh', sys.executable, '-m', 'rubber_rig.cli.main',
                               'conformance', *ARGS, *extra, '--junit', junit], capture_output=True, text=True,
                              timeout=600)
        found = verdicts(junit) if os.path.exists(junit) else {}
    fact = next((line for line in proc.stdout.splitlines() if 'host timing:' in line), proc.stderr[-300:])
    aborted = next((line.strip() for line in (proc.stdout + proc.stderr).splitlines()
                    if 'ABORTED:' in line or 'aborted:' in line), '')
    return proc.returncode, found, fact + ('\n  ' + aborted if aborted else '')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=3, help='consecutive runs (default 3)')
    parser.add_argument('--defect', action='append', default=[], help='a simulator defect (repeatable)')
    args = parser.parse_args(argv)
    if not (shutil.which('unshare') and shutil.which('ip')):
        print('needs unshare (util-linux) and ip (iproute2) for a private network namespace', file=sys.stderr)
        return 2
    extra = [x for d in args.defect for x in ('--defect', d)]
    tally = collections.defaultdict(collections.Counter)
    statuses = []
    for run in range(1, args.runs + 1):
        rc, found, fact = one_run(extra)
        statuses.append(rc)
        for rid, (verdict, _) in found.items():
            tally[rid][verdict] += 1
        failed = sorted(rid for rid, (v, _) in found.items() if v == 'FAIL')
        print(f'run {run}: exit status {rc}, load average {" ".join(f"{x:.2f}" for x in os.getloadavg())}, '
              f'failed: {", ".join(failed) or "none"}\n  {fact.strip()}', flush=True)
        for rid in failed:
            print(f'  FAIL {rid}: {found[rid][1][:300]}', flush=True)
    print(f'\n| requirement | pass | FAIL | not judged (host late) | of {args.runs} runs |')
    print('| --- | --- | --- | --- | --- |')
    for rid in sorted(set(TIMING) | {r for r, c in tally.items() if c['FAIL'] or c['not judged']}):
        c = tally[rid]
        print(f"| {rid} | {c['pass']} | {c['FAIL']} | {c['not judged']} | {sum(c.values())} |")
    print(f'\nexit statuses: {statuses}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
