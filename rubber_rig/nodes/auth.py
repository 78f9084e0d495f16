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

"""Signing and verifying the suite's messages in a node (the logic is rubber_rig.security's; this wires it).

Every node declares ``auth.key_file`` (the rig's key file; '' = RUBBER_RIG_KEY_FILE or
``~/.config/rubber_rig/rig.key``) and ``auth.required`` (default true). With auth.required and no usable key file
the node refuses to start (one line naming the file and ``rubber-rig keys init``; rubber_rig.nodes.spin). With
``auth.required: false`` (development only) and no key, the node signs nothing and accepts unsigned messages, and
says so in /diagnostics (WARN, ``auth: OFF``) and in its log; a signed message is still checked when there is a key.

What is signed (purpose string in the signature): ``setpoint_stream`` (the owner's command channel),
``setpoints`` (the public copy), ``samples``, ``heartbeat``, ``open_stream``, ``stop_stream``,
``recorder_control`` and ``run_program`` (the goal). The signature covers every field of the message except the
signature itself, header included (a message's content is its fields, from get_fields_and_field_types).
"""
from __future__ import annotations

import array
import os

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from ..security import KeyFileError, Signer, Verifier, default_key_path, load_key
from .params import ParameterError, declare
from .topics import DIAGNOSTICS

SETPOINT_STREAM, SETPOINTS, SAMPLES, HEARTBEAT = 'setpoint_stream', 'setpoints', 'samples', 'heartbeat'
OPEN_STREAM, STOP_STREAM = 'open_stream', 'stop_stream'
RECORDER_CONTROL, RUN_PROGRAM, HOLD_PROGRAM = 'recorder_control', 'run_program', 'hold_program'
SERVICE_PURPOSES = {'open_stream': OPEN_STREAM, 'stop_stream': STOP_STREAM, 'control': RECORDER_CONTROL,  # by name
                    'hold': HOLD_PROGRAM}


def fields_of(msg, prefix: str = '') -> list[tuple[str, object]]:
    """(dotted name, value) of every field of the ROS message `msg` but its signature, nested messages flattened in
    declaration order (what rubber_rig.security.canonical encodes).
    """
    out = []
    for name, nested in _layout(type(msg)):
        value = getattr(msg, name)
        if nested == 'message':
            out += fields_of(value, f'{prefix}{name}.')
        elif nested == 'sequence':
            out.append((f'{prefix}{name}.len', len(value)))
            for i, item in enumerate(value):
                out += fields_of(item, f'{prefix}{name}[{i}].')
        else:
            out.append((prefix + name, value))
    return out


_LAYOUTS: dict[type, list[tuple[str, str]]] = {}


def _layout(cls) -> list[tuple[str, str]]:
    """(field, 'message' | 'sequence' | '') of a message class, its signature left out (kept per class)."""
    layout = _LAYOUTS.get(cls)
    if layout is None:
        layout = _LAYOUTS[cls] = [
            (name, 'sequence' if kind.startswith('sequence<') and '/' in kind else 'message' if '/' in kind else '')
            for name, kind in cls.get_fields_and_field_types().items() if name != 'signature']
    return layout


class NodeAuth:
    """A node's signer and verifier. `key` None: no key (auth.required false)."""

    def __init__(self, link: str, key: bytes | None, required: bool, path: str):
        self.path, self.required, self.key = path, required, key
        self.signer = Signer(key, link) if key is not None else None
        self.verifier = Verifier(key, required)

    def sign(self, msg, purpose: str):
        """Fill msg.signature (when there is a key) and return msg."""
        if self.signer is not None:
            link, counter, tag = self.signer.sign(purpose, fields_of(msg))
            msg.signature.link, msg.signature.counter = link, counter
            msg.signature.tag = array.array('B', tag)
        return msg

    def verify(self, msg, purpose: str, where: str) -> str:
        """'' if `msg` (which came on channel `where`) may be used, else why it is refused (counted)."""
        sig = msg.signature
        return self.verifier.verify(purpose, where, sig.link, sig.counter, bytes(sig.tag), fields_of(msg))

    def refuse(self, node: Node, msg, purpose: str, where: str) -> bool:
        """Whether `msg` (from channel `where`) is refused; a refusal is counted and logged (at most once a second)."""
        why = self.verify(msg, purpose, where)
        if why:
            if self.verifier.due_to_say(purpose, where):    # once a second per channel: a flood on one channel
                node.get_logger().warning(                     # does not hide the refusals on another
                    f'{purpose} on {where} refused: {why} ({self.verifier.refused.get((purpose, where), 0)} so far)')
        return bool(why)

    def refuse_request(self, node: Node, request, purpose: str, response) -> bool:
        """Whether the service `request` (to ``<node>/<purpose>``) is refused; if so, `response` says why."""
        if not self.refuse(node, request, purpose, f'{node.get_fully_qualified_name()}/{purpose}'):
            return False
        response.success, response.message = False, f'refused: {self.verifier.last_refusal.why}'
        return True

    def lines(self) -> dict[str, str]:
        """/diagnostics values (auth mode, key file, refusals by channel, the latest refusal)."""
        return dict(self.verifier.lines(), auth_key_file=self.path)

    @property
    def off(self) -> bool:
        return self.key is None


def declare_auth(node: Node) -> NodeAuth:
    """Declare auth.key_file and auth.required on `node` and load the key (ParameterError if required and unusable)."""
    path = declare(node, 'auth.key_file', '', 'the rig\'s secret key file (mode 0600, `rubber-rig keys init`); '
                   'empty: $RUBBER_RIG_KEY_FILE, else ~/.config/rubber_rig/rig.key', read_only=True)
    required = declare(node, 'auth.required', True, 'refuse unsigned commands and samples (false: development only, '
                       'without a key anyone on the domain can move the rig)', read_only=True)
    path = str(path or default_key_path())
    try:
        key = load_key(path)
    except KeyFileError as exc:
        if required:
            raise ParameterError(node, 'auth.key_file', str(exc)) from None
        key = None
        node.get_logger().error(f'AUTHENTICATION OFF (auth.required false, {exc}): anyone on this ROS domain can '
                                'command the rig and forge its samples; for development only')
    return NodeAuth(node.get_fully_qualified_name(), key, required, path)


def annotate(status, auth: NodeAuth):
    """Add `auth`'s lines to the diagnostic_msgs/DiagnosticStatus `status`; at least WARN (and said first in its
    message) while authentication is off or once anything was refused: who sent it is in auth_last_refusal.
    """
    status.values.extend(KeyValue(key=k, value=str(v)) for k, v in auth.lines().items())
    refused = auth.verifier.refused_total
    if auth.off:
        status.message = f'AUTHENTICATION OFF (no key, auth.required false); {status.message}'
    elif refused:
        status.message = f'{refused} unauthenticated messages refused ({auth.verifier.last_refusal.describe()}); ' \
                         f'{status.message}'
    if auth.off or refused:
        status.level = max(status.level, DiagnosticStatus.WARN)
    return status


def start_auth_diagnostics(node: Node, auth: NodeAuth):
    """The function that publishes `auth`'s state on /diagnostics (status ``<node>/auth``), for a node that has no
    /diagnostics of its own: what it refused, from which channel, and why. The node calls it from its one timer
    (nodes/ticks.py).
    """
    pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS, 10)
    name = f'{node.get_fully_qualified_name()}/auth'

    def publish():
        msg = DiagnosticArray()
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.status.append(annotate(DiagnosticStatus(level=DiagnosticStatus.OK, name=name, hardware_id='rubber_rig',
                                                    message='signatures checked'), auth))
        pub.publish(msg)
    return publish


_CLIENTS: dict[tuple[str, str], NodeAuth] = {}


def client_auth(link: str, key_file: str | os.PathLike | None = None) -> NodeAuth:
    """The signer of a client (the CLI, the test operator, a script) named `link`: the key in `key_file`, else
    RUBBER_RIG_KEY_FILE, else ~/.config/rubber_rig/rig.key. Without a usable key file its messages go unsigned, and a
    rig that requires signatures refuses them, saying why. One per (link, key file): its counter only grows.
    """
    path = str(key_file or default_key_path())
    auth = _CLIENTS.get((link, path))
    if auth is None:
        try:
            key = load_key(path)
        except KeyFileError:
            key = None
        auth = _CLIENTS[(link, path)] = NodeAuth(link, key, False, path)
    return auth


def signed(msg, purpose: str, link: str = '/rubber_rig_client', key_file: str | os.PathLike | None = None):
    """`msg` signed for `purpose` by client `link` with the rig's key (client_auth); returns msg."""
    return client_auth(link, key_file).sign(msg, purpose)
