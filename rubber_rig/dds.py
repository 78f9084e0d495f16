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

"""The one DDS configuration of the suite, chosen from the environment before rclpy creates a participant.

- ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (the suite's default) without ``ROS_STATIC_PEERS`` or a profile
  file: the shipped ``config/fastdds_localhost.xml`` (UDPv4 on 127.0.0.1 only, no shared memory, unicast
  discovery of at most 64 participants). rmw is handed ``SYSTEM_DEFAULT`` so that it applies the file instead
  of its own LOCALHOST set-up, which adds shared memory whatever ``FASTDDS_BUILTIN_TRANSPORTS`` says.
- ``SUBNET``, or unset (a node started by hand, a suite over several hosts): rmw's SUBNET discovery with the
  shipped ``config/fastdds_subnet.xml`` (UDPv4 on every interface, no shared memory, 50 ms writer heartbeats:
  samples a network outage lost are repaired at once, not after Fast DDS's 3 s); ``FASTDDS_BUILTIN_TRANSPORTS``
  is UDPv4 for any participant the file does not set up.
- ``LOCALHOST`` with ``ROS_STATIC_PEERS``: rmw's own LOCALHOST set-up (UDPv4 and shared memory) with the peers.
- a profile file of the user's (``FASTRTPS_DEFAULT_PROFILES_FILE``): theirs, untouched.

Only Fast DDS (``rmw_fastrtps_cpp``, the suite's middleware) is configured; another RMW is left alone.
"""
from __future__ import annotations

import os

from .paths import find_config

RANGE_VARIABLE = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
PEERS_VARIABLE = 'ROS_STATIC_PEERS'
PROFILES_VARIABLE = 'FASTRTPS_DEFAULT_PROFILES_FILE'      # the name Fast DDS 2.14 (Jazzy) reads
TRANSPORTS_VARIABLE = 'FASTDDS_BUILTIN_TRANSPORTS'
LOCALHOST_PROFILE = 'fastdds_localhost.xml'
SUBNET_PROFILE = 'fastdds_subnet.xml'
PINNED_MARK = 'RUBBER_RIG_DDS'                            # says the suite chose (children keep the choice)


def configure_dds(environ=os.environ) -> str:
    """Set the DDS variables in `environ` (before rclpy.init) and return a one-line description of the
    configuration in effect (nodes log it at start). Idempotent: a child process inheriting a configured
    environment keeps it.
    """
    if environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp') != 'rmw_fastrtps_cpp':
        return f'RMW {environ["RMW_IMPLEMENTATION"]}: DDS configuration left to it'
    if environ.get(PINNED_MARK) and environ.get(PROFILES_VARIABLE):
        return environ[PINNED_MARK]
    if environ.get(PROFILES_VARIABLE):
        return f'Fast DDS profile file {environ[PROFILES_VARIABLE]} (chosen by the environment)'
    chosen = environ.get(RANGE_VARIABLE, '')
    if chosen == 'LOCALHOST' and not environ.get(PEERS_VARIABLE):
        profile = find_config(LOCALHOST_PROFILE)
        environ[PROFILES_VARIABLE] = str(profile)
        environ[RANGE_VARIABLE] = 'SYSTEM_DEFAULT'
        environ[PINNED_MARK] = (f'localhost only: Fast DDS profile {profile} (UDPv4 on 127.0.0.1, no shared '
                                'memory, unicast discovery of up to 64 participants)')
        return environ[PINNED_MARK]
    environ.setdefault(TRANSPORTS_VARIABLE, 'UDPv4')
    if chosen == 'LOCALHOST':
        return (f'localhost with static peers {environ[PEERS_VARIABLE]}: rmw_fastrtps LOCALHOST set-up (UDPv4 and '
                'shared memory)')
    profile = find_config(SUBNET_PROFILE)
    environ[PROFILES_VARIABLE] = str(profile)
    environ[PINNED_MARK] = (f'discovery range {chosen or "SUBNET (ROS default)"}: Fast DDS profile {profile} '
                            '(UDPv4 on every interface, no shared memory, 50 ms writer heartbeats)')
    return environ[PINNED_MARK]
