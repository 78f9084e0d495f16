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

"""The socket under python-can's udp_multicast bus: a receive queue deep enough for this host's stalls, and the
kernel's count of the datagrams it dropped because the queue was full.

Every process on the group receives every frame, its own included: at a 1 kHz rig about 1000 datagrams a
second. Linux's default receive queue (net.core.rmem_default, 212992 bytes, about 200 datagrams) then holds
0.2 s of traffic; a process that waits longer for a CPU loses frames - the host's loss, which a CAN controller
with its own mailboxes would not see. The separate-process simulator asks for RECEIVE_BUFFER (bus.open_bus; the
kernel caps it at net.core.rmem_max), and `dropped` reads the count of what was lost anyway, for the
conformance run's host timing (docs/protocol.md, "Host timing").
"""
import os
import socket

RECEIVE_BUFFER = 4 << 20    # [bytes] the simulator's receive queue (4 MiB: several seconds of traffic)
PROC_UDP = ('/proc/net/udp', '/proc/net/udp6')


def enlarge_receive_buffer(bus, size: int = RECEIVE_BUFFER) -> int:
    """Ask for a receive queue of `size` bytes on the socket of `bus` (anything with fileno()); returns the size
    the kernel granted (it doubles the request for bookkeeping and caps it at net.core.rmem_max), 0 if the bus has
    no socket.
    """
    try:
        fd = bus.fileno()
    except (AttributeError, NotImplementedError, OSError):
        return 0
    sock = socket.socket(fileno=os.dup(fd))      # the same socket; closing the duplicate leaves the bus's open
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
        return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    finally:
        sock.close()


def socket_inode(bus):
    """The inode of the socket under `bus` (its row in /proc/net/udp), None if it has none."""
    try:
        return os.fstat(bus.fileno()).st_ino
    except (AttributeError, NotImplementedError, OSError):
        return None


def dropped(inode, tables=PROC_UDP):
    """Datagrams the kernel dropped for the socket `inode` so far (the `drops` column of /proc/net/udp and udp6,
    in this process's network namespace), None where it is not listed.
    """
    if inode is None:
        return None
    for path in tables:
        try:
            with open(path, encoding='ascii') as f:
                lines = f.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) >= 13 and fields[9] == str(inode):
                return int(fields[12])
    return None
