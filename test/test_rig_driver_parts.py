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

"""The parts the driver and its node are built from, each on its own: the sample batcher (gaps, size, delay),
the live settings (checked as a whole, applied only when all fit), the stream's own continuity verdicts, and the
driver composed of FrameIO and Supervisor on a real simulated rig."""
import numpy as np

from rubber_rig.rig import open_rig
from rubber_rig.rig.can.batcher import SampleBatcher
from rubber_rig.rig.can.stream import GrantedStream, SampleBlock, StreamGrant
from rubber_rig.rig.config import RigConfig
from rubber_rig.rig.live import LIVE_SETTINGS, apply_live, review_change, weakening

from support.rig import FAST


def _block(first, n, lost=0, temperature=20.0):
    x = np.arange(first, first + n) * 1e-6
    return SampleBlock(first, first * 1e-3, 1e-3, x, 10 * x, x, temperature, 0, lost)


def test_the_batcher_gathers_whole_blocks_splits_at_gaps_and_releases_what_waits():
    now = [0.0]
    batcher = SampleBatcher(clock=lambda: now[0])
    assert batcher.add(_block(0, 4), 10) == [] and batcher.add(_block(4, 4), 10) == []
    done = batcher.add(_block(8, 4, temperature=21.0), 10)          # 12 >= 10: whole blocks, never split
    assert len(done) == 1 and done[0].first_sequence == 0 and len(done[0]) == 12
    assert np.array_equal(done[0].displacement, np.arange(12) * 1e-6) and done[0].temperature == 21.0
    assert batcher.add(_block(12, 3), 10) == []
    done = batcher.add(_block(20, 2, lost=5), 10)                   # 15..19 lost: the batch before the gap goes
    assert [(b.first_sequence, len(b), b.frames_lost) for b in done] == [(12, 3, 0)]
    now[0] = 0.05
    assert batcher.due(0.1) is None
    now[0] = 0.2                                                    # waited 0.2 s > 0.1 s: due as it is
    late = batcher.due(0.1)
    assert (late.first_sequence, len(late), late.frames_lost, late.t0) == (20, 2, 5, 0.02)
    assert batcher.due(0.1) is None and batcher.take() is None


def test_live_settings_apply_as_a_whole_or_not_at_all():
    cfg = RigConfig.from_dict({})
    before = cfg.limits.to_dict()
    why, limits = apply_live(cfg, {'limits.displacement_max': 0.004, 'rest_position': 0.005})
    assert 'rest_position 0.005 m outside' in why and limits is None
    assert cfg.limits.to_dict() == before and cfg.rest_position != 0.005          # nothing applied
    why, limits = apply_live(cfg, {'stream_loss_action': 'drift'})
    assert why.startswith('stream_loss_action: ') and cfg.stream_loss_action != 'drift'
    why, limits = apply_live(cfg, {'limits.displacement_max': 0.004, 'rest_position': 0.001,
                                   'stream_loss_action': 'hold', 'stream_timeout': 0.7})
    assert why == '' and limits.displacement_max == 0.004 and cfg.limits is limits
    assert (cfg.rest_position, cfg.stream_loss_action, cfg.stream_timeout) == (0.001, 'hold', 0.7)
    assert 'limits.force_max' in LIVE_SETTINGS and 'sample_rate' not in LIVE_SETTINGS


def test_a_granted_stream_judges_its_own_continuity():
    s = GrantedStream(StreamGrant(7, '/owner', 100, 0.0, 0.0), 100, 0.0, 0.0)
    assert s.refusal(100, 7) == '' and s.refusal(100, None) == ''
    assert 'not the open stream 7 of /owner' in s.refusal(100, 8)
    assert 'continues at 100' in s.refusal(101, 7)
    assert not s.playing(None)                              # nothing queued yet
    s.queued_end = 150
    assert s.playing(None) and s.playing(149) and not s.playing(150)
    assert s.why_not_reopen('/other').startswith('the rig is streaming for /owner')
    assert 'already has stream 7 open' in s.why_not_reopen('/owner')
    s.held = True
    assert s.why_not_reopen('/owner') == '' and not s.playing(120) and 'is held' in s.refusal(150, 7)
    cfg = RigConfig.from_dict({'paced': True, 'stream_timeout': 0.5})
    s.held = False
    assert s.lost(0.4, 120, False, cfg) == '' and 'for 0.600 s' in s.lost(0.6, 120, False, cfg)
    assert 'ran out of setpoints at sample 150' in s.lost(0.1, 150, True, cfg)


def test_the_driver_reads_its_parts_state_and_counts_every_sample():
    with open_rig(FAST) as rig:
        drv = rig.driver
        assert rig.wait_ready(5.0)
        assert drv.controller_state == drv.supervisor.controller_state == 'idle'
        assert drv.counters is drv.io.counters and drv.events is drv.supervisor.events
        x = 1e-4 * np.sin(np.linspace(0, 2 * np.pi, 500))
        assert drv.queue_setpoints(drv.next_sequence, x)
        got = 0
        for _ in range(200000):
            blk = drv.poll()
            got += len(blk) if blk is not None else 0
            if got >= 500:
                break
        st = drv.status
        assert st.setpoints_sent == 500 and st.samples_received == got >= 500 and st.frames_lost == 0
        at = drv.io.last_applied   # the last command the controller applied: the program's last setpoint
        assert st.faults == 0 and st.extra['position'] == at and abs(x[-1] - at) < 1e-6
        taken = drv.take_events()        # the log's lines leave the queue: each is logged once
        assert any('stream' in text and 'opened' in text for _, text in taken) and not drv.events
        assert drv.take_events() == []


def test_protective_settings_are_made_stricter_by_anyone_and_relaxed_only_to_the_configured_values():
    configured = {'limits.displacement_max': 5e-3, 'limits.displacement_min': -5e-3, 'limits.force_max': 60e3,
                  'stream_timeout': 0.3, 'owner_timeout': 1.0, 'rest_position': 0.0}
    tightened = dict(configured, **{'limits.displacement_max': 1e-3, 'stream_timeout': 0.1})
    # stricter: always, also under a running program
    assert weakening({'limits.displacement_max': 1e-3, 'limits.displacement_min': -1e-3, 'owner_timeout': 0.5},
                     configured, configured, stream_open=True) == ''
    # relaxed back towards the configured values: only with no stream open
    back = {'limits.displacement_max': 5e-3, 'stream_timeout': 0.3}
    assert weakening(back, tightened, configured, stream_open=False) == ''
    why = weakening(back, tightened, configured, stream_open=True)
    assert why.startswith('limits.displacement_max: 0.005 would relax the 0.001 in force while a stream is open')
    # beyond the configured values: never (the attack of issue 35: +-50 mm, 1e7 N, a 30 s owner timeout)
    for name, value in (('limits.displacement_max', 0.05), ('limits.displacement_min', -0.05),
                        ('limits.force_max', 1e7), ('owner_timeout', 30.0), ('stream_timeout', 5.0),
                        ('rest_position', 3e-3)):
        for stream_open in (False, True):
            why = weakening({name: value}, configured, configured, stream_open)
            assert why.startswith(f'{name}: {value:g} is beyond the configured') and 'restart rig_driver' in why
    # settings that protect nothing are not judged here
    assert weakening({'batch_size': 10, 'stream_loss_action': 'hold'}, configured, configured, True) == ''


def test_a_run_time_change_is_judged_as_a_whole_before_the_node_applies_it():
    """rig_driver's on_set_parameters takes review_change's verdict (the node applies it, test_nodes_safety.py)."""
    config = RigConfig.from_dict({})
    configured = {'limits.displacement_max': config.limits.displacement_max, 'owner_timeout': 1.0}
    live = LIVE_SETTINGS | {'batch_size', 'owner_timeout'}
    relax = review_change({'owner_timeout': 5.0}, configured, configured, False, True, config, live)
    assert relax.weakening and relax.why.startswith('owner_timeout: 5 is beyond the configured')
    fixed = review_change({'sample_rate': 500.0, 'batch_size': 5}, configured, configured, False, True, config, live)
    assert not fixed.weakening and fixed.why == \
        'sample_rate: applied at configure; the rig is configured (deactivate and clean up first)'
    assert review_change({'sample_rate': 500.0}, configured, configured, False, False, None, live).why == ''
    tighter = config.limits.displacement_max / 2
    taken = review_change({'limits.displacement_max': tighter}, configured, configured, True, True, config, live)
    assert taken.why == '' and taken.limits.displacement_max == tighter == config.limits.displacement_max
    bad = review_change({'rest_position': 1.0}, configured, configured, False, True, config, live)
    assert (bad.why, bad.weakening, bad.limits) == ('rest_position 1 m outside the displacement limits', False, None)
