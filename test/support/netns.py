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

"""A private network namespace for tests whose traffic (udp_multicast CAN) must not leave the machine: the
test re-runs itself inside a namespace that has only a loopback interface, with the multicast route on lo.
Creating one needs root, or unprivileged user namespaces; elsewhere such tests are skipped, never run on the
host's network.
"""
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
NETNS_MARK = 'RUBBER_RIG_TEST_PRIVATE_NETNS'     # set to the host's netns id in the re-run inside the namespace
NETNS_SETUP = 'ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec "$@"'


def netns_id(pid='self'):
    return os.readlink(f'/proc/{pid}/ns/net')


def unshare_command():
    """`unshare` arguments for a fresh network namespace set up for multicast on lo, or a skip reason."""
    unshare, ip = shutil.which('unshare'), shutil.which('ip')
    if unshare is None or ip is None:
        return None, ('the udp_multicast test needs a private network namespace: '
                      f'{"unshare (util-linux)" if unshare is None else "ip (iproute2)"} is not installed')
    cmd = [unshare, '--net']
    if os.geteuid() != 0:                 # unprivileged: a user namespace grants the network capabilities
        cmd = [unshare, '--user', '--map-root-user', '--net']
    probe = subprocess.run([*cmd, 'sh', '-c', NETNS_SETUP, 'sh', 'true'], capture_output=True, text=True,
                           timeout=30)
    if probe.returncode != 0:
        who = 'as root' if os.geteuid() == 0 else 'without root (user namespaces)'
        return None, (f'cannot create a private network namespace {who} for the udp_multicast test '
                      f'(unshare/ip: {probe.stderr.strip() or probe.returncode}); not running it on the host network')
    return [*cmd, 'sh', '-c', NETNS_SETUP, 'sh'], None


def multicast_routes():
    """IPv4 routes of this process's network namespace as (destination, mask, interface)."""
    routes = []
    for line in Path('/proc/self/net/route').read_text().splitlines()[1:]:
        iface, dest, _, _, _, _, _, mask = line.split()[:8]
        routes.append((socket.inet_ntoa(bytes.fromhex(dest)[::-1]), socket.inet_ntoa(bytes.fromhex(mask)[::-1]),
                       iface))
    return routes


def in_private_netns() -> bool:
    """True inside the re-run (and the namespace is proven private: only lo, multicast routed on lo)."""
    host = os.environ.get(NETNS_MARK)
    if host is None:
        return False
    assert netns_id() != host
    assert [name for _, name in socket.if_nameindex()] == ['lo']
    assert ('224.0.0.0', '240.0.0.0', 'lo') in multicast_routes()
    assert all(iface == 'lo' for _, _, iface in multicast_routes())
    return True


def rerun_in_private_netns(test_id: str, timeout: float = 270.0):
    """Run pytest on `test_id` inside a private network namespace; returns (returncode, output), or a skip
    reason as (None, reason).
    """
    prefix, reason = unshare_command()
    if prefix is None:
        return None, reason
    env = dict(os.environ, **{NETNS_MARK: netns_id()})
    proc = subprocess.run([*prefix, sys.executable, '-m', 'pytest', test_id, '-q', '-p', 'no:cacheprovider',
                           f'--timeout={int(timeout - 30)}'], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=timeout)
    return proc.returncode, proc.stdout[-6000:] + proc.stderr[-2000:]
