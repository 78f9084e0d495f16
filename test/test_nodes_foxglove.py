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

"""The Foxglove live view: the shipped layout is the generated one and only uses channels the node serves; a
WebSocket client speaking the Foxglove protocol (a minimal one written here: no client library is installed)
sees the channels advertised and receives live force samples after the node gets a ModelPrediction."""
import base64
import json
import os
import socket
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from rclpy.node import Node

from msg_defs.msg import DetectorEvent, ModelPrediction
from rubber_rig.excitation.detectors import Event
from rubber_rig.launching.inprocess import InProcessLauncher
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes import topics
from rubber_rig.nodes.foxglove_view_node import LAYOUT_FILE, FoxgloveViewNode, build_layout

from support.suite import domain_id

CHANNELS = {'/live/force', '/live/loop', '/live/cycle', '/live/status', '/live/events'}


def layout_paths(obj):
    if isinstance(obj, dict):
        for k, v in obj.items():
            if k in ('value', 'topicPath') and isinstance(v, str):
                yield v
            else:
                yield from layout_paths(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from layout_paths(v)


def test_shipped_layout_is_the_generated_one_and_uses_served_channels():
    assert LAYOUT_FILE == Path(__file__).resolve().parents[1] / 'config' / 'foxglove_layout.json'
    assert LAYOUT_FILE.read_text() == build_layout()
    layout = json.loads(LAYOUT_FILE.read_text())
    paths = list(layout_paths(layout))
    assert {p.split('.')[0] for p in paths} <= CHANNELS
    text = LAYOUT_FILE.read_text()
    for needed in ('/live/loop.displacement_mm[:]', '/live/loop.measured_kN[:]', '/live/loop.model_kN[:]',
                   '/live/force.measured_kN', '/live/force.model_kN', '/live/force.residual_kN'):
        assert needed in text


class FoxgloveClient:
    """Just enough of RFC 6455 and the Foxglove WebSocket protocol for a test."""

    def __init__(self, port: int, timeout: float = 20.0):
        self.sock = socket.create_connection(('127.0.0.1', port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f'GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n'
                           f'Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n'
                           'Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n').encode())
        head = b''
        while b'\r\n\r\n' not in head:
            head += self.sock.recv(1)
        assert b' 101 ' in head.split(b'\r\n')[0], head

    def _read(self, n: int) -> bytes:
        data = b''
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            assert chunk, 'connection closed'
            data += chunk
        return data

    def frame(self) -> tuple[int, bytes]:
        b0, b1 = self._read(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack('>H', self._read(2))[0]
        elif n == 127:
            n = struct.unpack('>Q', self._read(8))[0]
        return b0 & 0x0F, self._read(n)

    def send_text(self, text: str) -> None:
        payload, mask = text.encode(), os.urandom(4)
        n = len(payload)
        head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack('>H', n))
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))


@pytest.mark.ros
def test_live_view_serves_force_samples_over_websocket():
    port = 20000 + os.getpid() % 20000
    with InProcessLauncher(domain_id=domain_id()) as launcher:
        launcher.start(FoxgloveViewNode, {'port': port, 'live_rate': 100.0})
        feeder = Node('feeder', context=launcher.context)
        pub = feeder.create_publisher(ModelPrediction, topics.PREDICTION, topics.STREAM_QOS)
        client = FoxgloveClient(port)
        channels = {}
        deadline = time.monotonic() + 20
        while set(channels) < CHANNELS and time.monotonic() < deadline:
            op, data = client.frame()
            if op == 1:
                msg = json.loads(data)
                if msg.get('op') == 'advertise':
                    channels.update({c['topic']: c for c in msg['channels']})
        assert CHANNELS <= set(channels)
        assert channels['/live/force']['encoding'] == 'json'
        client.send_text(json.dumps({'op': 'subscribe', 'subscriptions': [
            {'id': 7, 'channelId': channels['/live/force']['id']}]}))
        x = 1e-3 * np.sin(np.linspace(0, np.pi, 50))
        batch = conv.sample_batch_msg(1000, time.time(), 1e-3, x, 1.5e7 * x, x, 20.0, 0, 0)
        received = []
        deadline = time.monotonic() + 20
        while not received and time.monotonic() < deadline:
            pub.publish(conv.prediction_msg(batch, 1.5e7 * x - 3.0))
            client.sock.settimeout(0.5)
            try:
                while not received:
                    op, data = client.frame()
                    if op == 2 and data[0] == 0x01:
                        sub_id, _stamp = struct.unpack('<IQ', data[1:13])
                        received.append((sub_id, json.loads(data[13:])))
            except socket.timeout:
                pass
        assert received, 'no /live/force message over the WebSocket'
        sub_id, sample = received[0]
        assert sub_id == 7
        assert sample['sequence'] % 10 == 0          # decimated to 100 Hz on the sequence grid
        i = sample['sequence'] - 1000
        assert sample['displacement_mm'] == pytest.approx(x[i] * 1e3)
        assert sample['measured_kN'] == pytest.approx(1.5e7 * x[i] * 1e-3)
        assert sample['residual_kN'] == pytest.approx(3.0e-3)

        # a detector event reaches the events table (and the K_dyn plot's markers)
        client.send_text(json.dumps({'op': 'subscribe', 'subscriptions': [
            {'id': 8, 'channelId': channels['/live/events']['id']}]}))
        events = feeder.create_publisher(DetectorEvent, topics.EVENTS, topics.EVENT_QOS)
        event = Event('crack', 'residual', 2, 17, 41, 12.5, 2400.0, 150.0, 600.0, 'N', 'hold', 'a crack', 12500)
        got = []
        deadline = time.monotonic() + 20
        while not got and time.monotonic() < deadline:
            events.publish(conv.detector_event_msg(event, 'durability_10hz', 'durability', time.time()))
            try:
                while not got:
                    op, data = client.frame()
                    if op == 2 and data[0] == 0x01 and struct.unpack('<I', data[1:5])[0] == 8:
                        got.append(json.loads(data[13:]))
            except socket.timeout:
                pass
        assert got, 'no /live/events message over the WebSocket'
        assert (got[0]['detector'], got[0]['action'], got[0]['cycle'], got[0]['block_name']) == \
            ('crack', 'hold', 17, 'durability')
