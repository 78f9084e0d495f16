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

"""Heartbeats (rubber_rig.nodes.heartbeat): a node whose executor stops is named silent by a watcher within a
second of its last beat, a restarted one (new pid) is counted, and a node never heard from is not silent."""
import os
import time

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from msg_defs.msg import Heartbeat
from rubber_rig.nodes.heartbeat import PERIOD, SILENT, OwnerWatch, Peers, start_heartbeat
from rubber_rig.nodes.monitor import SuiteMonitor
from rubber_rig.rig.can.stream import StreamGrant

from support.ros import ros_context

pytestmark = pytest.mark.ros
DOMAIN = 90 + os.getpid() % 10


@pytest.mark.system      # "within a second" on the wall clock of a SIGSTOPped process; the rule is
#                          session.liveness.Peers', judged on simulated time in test_scenario_faults
def test_a_node_whose_executor_stops_is_named_silent_within_a_second():
    with ros_context(DOMAIN) as ctx:
        beating = Node('beating', namespace='/hb', context=ctx)
        start_heartbeat(beating, lambda: 'busy')
        watcher = SuiteMonitor(node_name='watcher', namespace='/hb', context=ctx)
        peers = watcher.peers
        both, alone = SingleThreadedExecutor(context=ctx), SingleThreadedExecutor(context=ctx)
        both.add_node(beating)
        both.add_node(watcher)
        t0 = time.monotonic()
        while time.monotonic() - t0 < 5.0 and '/hb/beating' not in peers.last:
            both.spin_once(timeout_sec=0.05)
        assert '/hb/beating' in peers.last, 'no beat received'
        while time.monotonic() - t0 < 6.0:
            both.spin_once(timeout_sec=0.05)
        beat = peers.last['/hb/beating'][1]
        assert beat.state == 'busy' and beat.pid == os.getpid() and beat.count >= 4 / PERIOD - 4
        assert peers.silent() == {} and peers.describe() == ''
        assert peers.silent(['/hb/never_started']) == {}          # never heard: not silent
        # the beating node's executor stops (as a node stuck in a callback or in DDS): only the watcher spins
        both.remove_node(watcher)
        alone.add_node(watcher)
        stopped = time.monotonic()
        while not peers.silent() and time.monotonic() - stopped < 3.0:
            alone.spin_once(timeout_sec=0.02)
        now = time.monotonic()
        named, since_beat = now - stopped, now - peers.last['/hb/beating'][0]
        assert '/hb/beating' in peers.silent(), 'never named silent'
        # the silence is counted from the last beat received, which came up to one PERIOD before the executor
        # stopped: named SILENT after that beat (one spin of 20 ms late at most), never later than SILENT + PERIOD
        # after the stop
        assert SILENT <= since_beat <= SILENT + 0.1, since_beat
        assert SILENT - PERIOD <= named <= SILENT + PERIOD + 0.1, named
        assert peers.describe().startswith('silent: /hb/beating (')
        # it beats again with a new pid: a restart, counted, no longer silent
        peers.on_beat(type(beat)(node='/hb/beating', pid=beat.pid + 1, count=0, state='idle'))
        assert peers.restarts == {'/hb/beating': 1} and peers.silent() == {}
        for ex in (both, alone):
            ex.shutdown()
        beating.destroy_node()
        watcher.destroy_node()


def test_a_restarted_owner_is_judged_from_its_grant_not_by_its_predecessors_last_beat():
    """rig_driver's owner watch (owner_timeout 1 s here) on a clock the test moves: the excitation beat, was
    killed, and its restart opens a stream 2.5 s later, before its own first beat has arrived. The stream is not
    lost at once for its predecessor's silence; a new owner that never beats loses it after owner_timeout."""
    clock = [100.0]
    with ros_context(DOMAIN) as ctx:
        node = Node('driver', namespace='/hb', context=ctx)
        try:
            peers = Peers(node, silent=1.0, clock=lambda: clock[0])
            watch = OwnerWatch(peers)
            peers.on_beat(Heartbeat(node='/hb/excitation', pid=1, count=7))
            clock[0] += 2.5
            grant = StreamGrant(stream_id=2, owner='/hb/excitation', first_sequence=5000, position=0.0, velocity=0.0)
            assert peers.age('/hb/excitation') == pytest.approx(2.5)
            assert watch.silent_for(grant) == pytest.approx(0.0)
            clock[0] += 0.6
            assert watch.silent_for(grant) == pytest.approx(0.6)      # counted from the grant
            peers.on_beat(Heartbeat(node='/hb/excitation', pid=2, count=0))
            assert peers.restarts == {'/hb/excitation': 1}
            clock[0] += 0.3
            assert watch.silent_for(grant) == pytest.approx(0.3)      # from its own last beat
            clock[0] += 1.2                                           # the new owner stops beating
            assert watch.silent_for(grant) == pytest.approx(1.5) and watch.silent_for(grant) > peers.silent_after
            # a restarted owner that never beats: silent from the grant, lost after owner_timeout like any other
            peers.on_beat(Heartbeat(node='/hb/excitation', pid=3, count=0))
            clock[0] += 4.0
            again = StreamGrant(stream_id=3, owner='/hb/excitation', first_sequence=9000, position=0.0, velocity=0.0)
            assert watch.silent_for(again) == pytest.approx(0.0)
            clock[0] += 1.1
            assert watch.silent_for(again) == pytest.approx(1.1) and watch.silent_for(again) > peers.silent_after
            # a client that never beats is never judged silent (it may not run a heartbeat at all)
            client = StreamGrant(stream_id=4, owner='/hb/cli', first_sequence=0, position=0.0, velocity=0.0)
            assert watch.silent_for(client) is None
        finally:
            node.destroy_node()
