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

"""Hold the running program at its block mean, or resume a held one (signed with the rig's key).

``rubber-rig hold [--namespace /rig1]`` holds; ``rubber-rig hold --resume`` resumes with the cycles the block still
owes (also after a detector's hold). A resume moves the rig, so the excitation takes it only signed with the rig's
key (README "Who may move the rig"); ``ros2 service call <ns>/excitation/hold msg_defs/srv/HoldProgram
"{data: true}"`` still holds without a key, as anyone may stop a test.
"""
from __future__ import annotations

import argparse

import rclpy
from rclpy.node import Node

from msg_defs.srv import HoldProgram
from rubber_rig.launching.inprocess import InProcessLauncher
from rubber_rig.nodes.auth import HOLD_PROGRAM, signed


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--resume', action='store_true', help='resume the held program (default: hold it)')
    parser.add_argument('--namespace', default='', help='the suite\'s namespace (e.g. /rig1)')
    parser.add_argument('--key-file', help='the rig\'s key (default: $RUBBER_RIG_KEY_FILE, else '
                        '~/.config/rubber_rig/rig.key)')
    parser.add_argument('--timeout', type=float, default=10.0, help='seconds to wait for the excitation [s]')


def run(args) -> int:
    with InProcessLauncher(namespace=args.namespace) as launcher:     # the suite's DDS configuration
        node = Node('rubber_rig_hold', namespace=args.namespace or '/', context=launcher.context)
        client = node.create_client(HoldProgram, 'excitation/hold')
        if not client.wait_for_service(timeout_sec=args.timeout):
            raise ValueError(f'no excitation/hold service in namespace {args.namespace or "/"} within '
                             f'{args.timeout:g} s (is the suite running, on this ROS_DOMAIN_ID?)')
        request = signed(HoldProgram.Request(data=not args.resume), HOLD_PROGRAM, node.get_fully_qualified_name(),
                         args.key_file)
        future = client.call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=args.timeout, executor=None)
        if not future.done():
            raise ValueError(f'excitation/hold did not answer within {args.timeout:g} s')
        response = future.result()
        print(response.message)
        return 0 if response.success else 1
