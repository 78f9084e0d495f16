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

"""Liveness from heartbeats (session.liveness) on simulated time: the owner watch and the silent owner rig_driver
names in /diagnostics, at their boundaries. The node's heartbeat subscription is tested in test_heartbeat.py.
"""
from dataclasses import dataclass

from rubber_rig.session.liveness import SILENT, OwnerSilence, OwnerWatch, Peers

OWNER = '/rig1/excitation'


@dataclass
class Beat:
    node: str
    pid: int


@dataclass
class Grant:
    owner: str


def test_the_owner_watch_takes_the_stream_after_exactly_owner_timeout_of_silence():
    now = [100.0]
    peers = Peers(silent=1.0, clock=lambda: now[0])
    watch, grant = OwnerWatch(peers), Grant(OWNER)
    assert watch.lost(grant, 1.0) == ''                             # never heard: a client that does not beat
    peers.on_beat(Beat(OWNER, 7))
    now[0] = 101.0
    assert watch.lost(grant, 1.0) == ''                             # exactly owner_timeout
    now[0] = 101.0 + 1 / 1024
    assert watch.lost(grant, 1.0) == f'{OWNER} silent for 1.00 s (no heartbeat; alive but stuck, or gone)'
    restarted = Grant(OWNER)                                         # a new grant: its silence counts from the grant
    assert watch.lost(restarted, 1.0) == ''


def test_the_silent_owner_is_news_once_and_named_until_it_beats_again():
    now = [100.0]
    peers = Peers(silent=1.0, clock=lambda: now[0])
    silence = OwnerSilence(peers)
    assert silence.limit() == SILENT                                 # the shorter of owner_timeout and SILENT
    assert silence.update('', 'running', 0)                          # the first status is news
    assert not silence.update('', 'running', 0) and silence.lines() == {}
    assert silence.update('', 'fault', 1)                            # a fault is news
    assert not silence.update('', 'fault', 1)
    peers.on_beat(Beat(OWNER, 7))
    assert silence.update(OWNER, 'running', 0) and not silence.is_silent()   # the fault cleared
    now[0] = 100.0 + SILENT                                          # exactly SILENT: not yet
    assert not silence.update('', 'running', 0) and silence.lines() == {}
    now[0] = 100.0 + SILENT + 1 / 1024
    assert silence.update('', 'running', 0)                          # news: /diagnostics at once
    assert silence.lines() == {'silent_stream_owner': OWNER, 'silent_stream_owner_for_s': '0.75'}
    assert not silence.update('', 'running', 0)
    peers.on_beat(Beat(OWNER, 7))
    assert silence.update('', 'running', 0)
    assert silence.lines() == {'silent_stream_owner': '', 'last_silent_stream_owner': f'{OWNER} (beats again)'}
    assert silence.lines() == {}
