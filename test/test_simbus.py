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

"""The simulated CAN bus segment (rubber_rig.rig.can.simbus): bit timing, arbitration, queues, load, threads."""
import math
import threading
import time

import can
import pytest

from rubber_rig.rig.can.simbus import BusMedium, TimedBus, arbitration_key
from rubber_rig.rig.can.timing import frame_time

T0 = 100.0


class FakeClock:
    """A clock that stands still until a test sets it."""

    def __init__(self, t=T0):
        self.t = t

    def __call__(self):
        return self.t


def frame(arbitration_id, n=8, data=None, **kwargs):
    kwargs.setdefault('is_extended_id', False)
    return can.Message(arbitration_id=arbitration_id, data=bytes(n) if data is None else data, **kwargs)


def drain(bus):
    out = []
    while (msg := bus.recv(0)) is not None:
        out.append(msg)
    return out


@pytest.fixture
def clock():
    return FakeClock()


@pytest.fixture
def media():
    made = []

    def make(**kwargs):
        medium = BusMedium(**kwargs)
        made.append(medium)
        return medium

    yield make
    for medium in made:
        for node in list(medium._nodes):
            node.shutdown()


def test_a_classic_frame_arrives_exactly_its_duration_after_send(clock, media):
    before = time.time() - T0
    medium = media(bitrate=500e3, fd=False, clock=clock)
    after = time.time() - T0
    a, b = medium.attach('a'), medium.attach('b')
    assert isinstance(a, TimedBus) and a.medium is medium and a.protocol == can.CanProtocol.CAN_20
    duration = frame_time(8, 500e3)
    assert duration == pytest.approx(270e-6)          # 135 bits worst case at 500 kbit/s
    a.send(frame(0x123, data=bytes(range(8))))
    clock.t = T0 + duration - 1e-9
    assert b.recv(0) is None                          # still on the bus
    assert medium.stats['frames_transmitted'] == 0 and medium.stats['busy_time'] == pytest.approx(duration - 1e-9)
    clock.t = T0 + duration
    got = b.recv(0)
    assert got.arbitration_id == 0x123 and got.data == bytearray(range(8)) and not got.is_extended_id
    assert got.is_rx and got.channel == medium.name and got.dlc == 8 and not got.is_fd
    # arrival on the medium's clock, expressed on time.time()'s scale
    assert before - 1e-6 <= got.timestamp - (T0 + duration) <= after + 1e-6
    assert a.recv(0) is None                          # no own messages
    assert b.recv(0) is None
    assert a.frames_sent == 1 and b.frames_sent == 0 and a.max_queue_delay == 0.0
    stats = medium.stats
    assert stats['frames_transmitted'] == 1 and stats['busy_time'] == pytest.approx(duration)
    assert stats['frames_dropped'] == 0 and stats['nodes'] == 2


def test_an_fd_frame_runs_its_data_phase_at_the_data_bitrate(clock, media):
    medium = media(bitrate=1e6, data_bitrate=5e6, fd=True, clock=clock)
    a, b = medium.attach(), medium.attach()
    assert a.name != b.name and a.protocol == can.CanProtocol.CAN_FD
    brs = frame_time(64, 1e6, 5e6, fd=True)
    # 34 bits at 1 Mbit/s (arbitration, tail) + 678 at 5 Mbit/s (ESI, DLC, 512 data, stuff count, CRC-21, stuffing)
    assert brs == pytest.approx(34e-6 + 678 / 5e6)
    a.send(frame(0x10, 64, is_fd=True, bitrate_switch=True))
    clock.t = T0 + brs - 1e-9
    assert b.recv(0) is None
    clock.t = T0 + brs
    got = b.recv(0)
    assert got.is_fd and got.bitrate_switch and len(got.data) == 64
    # without bit-rate switch the whole frame runs at the nominal bitrate
    a.send(frame(0x10, 64, is_fd=True, bitrate_switch=False))
    assert frame_time(64, 1e6, 5e6, fd=True, bitrate_switch=False) == pytest.approx(712e-6)
    clock.t = T0 + brs + 712e-6 - 1e-9
    assert b.recv(0) is None
    clock.t = T0 + brs + 712e-6 + 1e-9
    assert not b.recv(0).bitrate_switch


def test_a_29_bit_identifier_lengthens_the_frame(clock, media):
    medium = media(bitrate=1e6, fd=False, clock=clock)
    a, b = medium.attach(), medium.attach()
    a.send(frame(0x1ABCDE, is_extended_id=True))
    clock.t = T0 + 160e-6 - 1e-9            # 118 stuffed bits + 29 stuff bits + 13: 160 bits at 1 Mbit/s
    assert b.recv(0) is None
    clock.t = T0 + 160e-6 + 1e-9
    assert b.recv(0).is_extended_id


def test_the_lowest_identifier_wins_arbitration_between_nodes_each_node_sends_in_order(clock, media):
    medium = media(bitrate=1e6, fd=False, clock=clock)
    a, b, e, c = medium.attach('a'), medium.attach('b'), medium.attach('e'), medium.attach('c')
    d = frame_time(8, 1e6)
    b.send(frame(0x100))                    # on the bus from T0 to T0 + d
    clock.t = T0 + 10e-6
    a.send(frame(0x300))
    a.send(frame(0x250, data=b'first..8'))
    a.send(frame(0x200))
    e.send(frame(0x280))
    e.send(frame(0x250, data=b'second.8'))
    assert a.frames_queued == 3 and e.frames_queued == 2
    clock.t = T0 + 1.0
    got = drain(c)
    # heads after 0x100: a 0x300, e 0x280 -> 0x280; then a 0x300 vs e 0x250 -> 0x250; then a's queue in order
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == [
        (0x100, bytes(8)), (0x280, bytes(8)), (0x250, b'second.8'), (0x300, bytes(8)), (0x250, b'first..8'),
        (0x200, bytes(8))]
    # back to back: each frame ends one frame duration [s] after the previous (timestamps on time.time()'s
    # scale resolve 0.24 us)
    ends = [m.timestamp - got[0].timestamp for m in got]
    assert ends == pytest.approx([0, d, 2 * d, 3 * d, 4 * d, 5 * d], abs=5e-7)
    assert a.max_queue_delay == pytest.approx(5 * d - 10e-6)   # 0x200 waited for 0x100, e's two and a's two
    assert medium.stats['max_queue_delay'] == pytest.approx(5 * d - 10e-6)
    assert [m.arbitration_id for m in drain(a)] == [0x100, 0x280, 0x250] and len(drain(b)) == 5


@pytest.mark.parametrize('late, order', [(0.0, [0x100, 0x050, 0x300]), (1e-6, [0x100, 0x300, 0x050])],
                         ids=['queued-at-the-moment', 'queued-after-the-moment'])
def test_only_frames_queued_by_the_arbitration_moment_take_part(clock, media, late, order):
    medium = media(bitrate=1e6, fd=False, clock=clock)
    a, b, c, listener = (medium.attach() for _ in range(4))
    d = frame_time(8, 1e6)
    b.send(frame(0x100))
    clock.t = T0 + 10e-6
    a.send(frame(0x300))
    clock.t = T0 + d + late                 # the bus becomes free at T0 + d
    c.send(frame(0x050))
    clock.t = T0 + 1.0
    got = drain(listener)
    assert [m.arbitration_id for m in got] == order
    assert got[-1].timestamp - got[0].timestamp == pytest.approx(2 * d, abs=5e-7)   # back to back either way


def test_arbitration_compares_the_fields_bit_by_bit():
    assert arbitration_key(0x100) < arbitration_key(0x101) < arbitration_key(0x7FF)
    assert arbitration_key(0x100) < arbitration_key(0x100, remote=True)      # RTR recessive
    # the base identifier (top 11 bits) of a 29-bit identifier comes first on the wire
    assert arbitration_key(0x00040000, extended=True) < arbitration_key(0x005)
    # same base identifier: SRR and IDE are recessive, so the 11-bit frame wins, even a remote one
    assert arbitration_key(0x001, remote=True) < arbitration_key(0x00040000, extended=True)
    assert arbitration_key(0x00040000, extended=True) < arbitration_key(0x00040001, extended=True)


def test_a_burst_beyond_the_transmit_queue_is_dropped(clock, media):
    medium = media(bitrate=1e6, fd=False, tx_queue=8, clock=clock)
    a, b = medium.attach(), medium.attach()
    refused = 0
    for i in range(20):
        try:
            a.send(frame(0x100 + i))
        except can.CanOperationError as e:
            assert 'transmit buffer full' in str(e)
            refused += 1
    assert refused == 12 and a.frames_dropped == 12 and medium.stats['frames_dropped'] == 12
    clock.t = T0 + 1.0
    assert [m.arbitration_id for m in drain(b)] == list(range(0x100, 0x108))


def test_an_offered_load_above_the_bitrate_first_delays_then_drops(clock, media):
    queue, offered = 10, 300
    medium = media(bitrate=1e6, fd=False, tx_queue=queue, clock=clock)
    a, b = medium.attach(), medium.attach()
    d = frame_time(8, 1e6)
    period = d / math.sqrt(3)               # 1.73 times what the bus carries; never in step with the frames
    first_drop = None
    for k in range(offered):
        clock.t = T0 + k * period
        try:
            a.send(frame(0x100))
        except can.CanOperationError:
            first_drop = k if first_drop is None else first_drop
    # the bus is busy from T0 on; by the last send ceil(t / d) frames have started and the queue is full
    accepted = math.ceil((offered - 1) * period / d) + queue
    assert a.frames_dropped == offered - accepted == medium.stats['frames_dropped']
    # no loss until the queue has filled: it grows by (1 - period / d) frames per send
    assert first_drop == pytest.approx(queue / (1 - period / d), abs=2)
    # a frame waits for the queue ahead of it and the rest of the frame on the bus
    assert (queue - 1) * d < a.max_queue_delay <= queue * d
    clock.t = T0 + 1.0
    delivered = len(drain(b))
    assert delivered == accepted == a.frames_sent and delivered + a.frames_dropped == offered


def test_load_is_the_busy_fraction_of_the_window(clock, media):
    medium = media(bitrate=1e6, fd=False, clock=clock, load_window=0.01)
    a, _ = medium.attach(), medium.attach()
    for _ in range(100):                    # 13.5 ms of frames back to back
        a.send(frame(0x100))
    clock.t = T0 + 0.012
    assert medium.load() == pytest.approx(1.0, abs=1e-9)
    assert medium.load(0.005) == pytest.approx(1.0, abs=1e-9)
    clock.t = T0 + 0.0135 + 0.005           # the last frame ended 5 ms ago
    assert medium.load() == pytest.approx(0.5, abs=1e-6)
    with pytest.raises(ValueError, match='load window'):
        medium.load(0.02)


def test_load_of_a_periodic_frame(clock, media):
    medium = media(bitrate=1e6, fd=False, clock=clock)
    a, b = medium.attach(), medium.attach()
    for k in range(1200):                   # one 8-byte frame every 1 ms for 1.2 s
        clock.t = T0 + k * 1e-3
        a.send(frame(0x100))
    clock.t = T0 + 1.2
    d = frame_time(8, 1e6)
    assert medium.load() == pytest.approx(d / 1e-3, rel=0.01)
    assert medium.load(0.5) == pytest.approx(d / 1e-3, rel=0.01)
    assert medium.stats['busy_time'] == pytest.approx(1200 * d)
    assert medium.stats['max_queue_delay'] == 0.0
    assert len(drain(b)) == 1200


def test_a_classic_bus_refuses_fd_frames(clock, media):
    medium = media(bitrate=500e3, fd=False, clock=clock)
    a, b = medium.attach(), medium.attach()
    assert medium.data_bitrate is None
    with pytest.raises(can.CanOperationError, match='classic CAN bus.*CAN FD frame 0x10'):
        a.send(frame(0x10, 12, is_fd=True, bitrate_switch=True))
    with pytest.raises(can.CanOperationError, match='0-8 bytes'):
        a.send(frame(0x10, 12))
    a.send(frame(0x10, 8))                  # the node still works
    clock.t = T0 + 1.0
    assert len(drain(b)) == 1 and medium.stats['frames_dropped'] == 0


def test_a_blocked_receiver_wakes_when_another_thread_sends():
    medium = BusMedium(bitrate=125e3, fd=False)     # real clock; an 8-byte frame takes 1.08 ms
    a, b = medium.attach(), medium.attach()
    duration = frame_time(8, 125e3)
    result = {}

    def receive():
        result['msg'] = b.recv(1.0)
        result['at'] = time.monotonic()

    try:
        thread = threading.Thread(target=receive)
        thread.start()
        time.sleep(0.05)
        sent = time.monotonic()
        a.send(frame(0x42))
        thread.join(2.0)
        assert not thread.is_alive() and result['msg'].arbitration_id == 0x42
        assert duration <= result['at'] - sent < 0.5        # woken by the send, not by the timeout
        assert result['msg'].timestamp <= time.time()
        t = time.monotonic()
        assert b.recv(0.05) is None and time.monotonic() - t >= 0.05
    finally:
        a.shutdown()
        b.shutdown()


def test_shutdown_detaches_one_node(clock, media):
    medium = media(bitrate=1e6, fd=False, clock=clock)
    a, b, c = medium.attach('a'), medium.attach('b'), medium.attach('c')
    d = frame_time(8, 1e6)
    a.send(frame(0x101))
    a.send(frame(0x102))
    clock.t = T0 + 1e-6                     # 0x101 is on the bus, 0x102 waits
    a.shutdown()
    a.shutdown()                            # twice is harmless
    stats = medium.stats
    assert stats['frames_discarded'] == 1 and stats['nodes'] == 2 and stats['frames_queued'] == 0
    with pytest.raises(can.CanOperationError, match='shut down'):
        a.send(frame(0x103))
    with pytest.raises(can.CanOperationError, match='shut down'):
        a.recv(0)
    c.send(frame(0x200))
    clock.t = T0 + 1.0
    assert [m.arbitration_id for m in drain(b)] == [0x101, 0x200]
    got = drain(c)
    assert [m.arbitration_id for m in got] == [0x101]
    assert got[0].timestamp - medium.time_offset == pytest.approx(T0 + d, abs=5e-7)


def test_flush_tx_buffer_discards_the_frames_not_yet_on_the_bus(clock, media):
    medium = media(bitrate=1e6, fd=False, clock=clock)
    a, b = medium.attach(), medium.attach()
    for i in range(3):
        a.send(frame(0x100 + i))
    clock.t = T0 + 1e-6                     # 0x100 is on the bus
    a.flush_tx_buffer()
    assert a.frames_queued == 0 and medium.stats['frames_discarded'] == 2
    a.send(frame(0x200))                    # waits for 0x100 to end
    clock.t = T0 + 1.0
    got = drain(b)
    assert [m.arbitration_id for m in got] == [0x100, 0x200]
    assert got[1].timestamp - got[0].timestamp == pytest.approx(frame_time(8, 1e6), abs=5e-7)


def test_shutdown_wakes_a_blocked_receiver():
    medium = BusMedium()
    a, b = medium.attach(), medium.attach()
    errors = []

    def receive():
        try:
            a.recv(None)
        except can.CanOperationError as e:
            errors.append(e)

    thread = threading.Thread(target=receive)
    thread.start()
    time.sleep(0.05)
    a.shutdown()
    thread.join(1.0)
    b.shutdown()
    assert not thread.is_alive() and len(errors) == 1
