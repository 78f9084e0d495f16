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

"""Opening the python-can Bus chosen by configuration (one abstract Bus, interchangeable interfaces)."""
import importlib
import itertools
import os

import can

from .udp_socket import enlarge_receive_buffer

_counter = itertools.count()


def sim_channel_name() -> str:
    """A fresh in-process virtual channel, so two rigs in one process never share a bus by accident."""
    return f'rubber_rig_sim_{os.getpid()}_{next(_counter)}'


def open_bus(config, channel=None, receive_buffer: int = 0) -> can.BusABC:
    """python-can Bus for RigConfig `config`: the virtual interface for the in-process "sim" backend,
    otherwise config.backend with channel, bitrates, fd and bus_options. receive_buffer [bytes]: with
    udp_multicast, the receive queue to ask for (udp_socket.RECEIVE_BUFFER for the simulator; 0: the kernel's
    default).
    """
    if config.backend == 'sim':
        return can.Bus(interface='virtual', channel=channel or sim_channel_name(), receive_own_messages=False)
    kwargs = dict(config.bus_options)
    if config.backend == 'virtual':
        return can.Bus(interface='virtual', channel=channel or config.channel or 'rubber_rig', **kwargs)
    if config.backend == 'udp_multicast':
        udp = importlib.import_module('can.interfaces.udp_multicast')   # needs msgpack
        kwargs.setdefault('fd', config.fd)
        kwargs.setdefault('hop_limit', 0)   # frames stay on this host unless the user asks (bus_options)
        bus = can.Bus(interface='udp_multicast', channel=channel or config.channel or
                      udp.UdpMulticastBus.DEFAULT_GROUP_IPv4, **kwargs)
        if receive_buffer:      # frames that arrive while this process waits for a CPU stay queued
            enlarge_receive_buffer(bus, receive_buffer)
        return bus
    kwargs.setdefault('bitrate', config.bitrate)
    if config.fd:
        kwargs.setdefault('fd', True)
        kwargs.setdefault('data_bitrate', config.data_bitrate)
    return can.Bus(interface=config.backend, channel=channel or config.channel, **kwargs)
