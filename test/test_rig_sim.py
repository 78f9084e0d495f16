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

"""Driver + simulated rig through python-can (real virtual bus, DBC encode/decode both ways): every waveform,
measured signals against the actuator and specimen models, amplitude control, paced == fast, temperature."""
import math

import numpy as np
import pytest

from rubber_rig.excitation import Program, load_program
from rubber_rig.rig import RigConfig, open_rig
from rubber_rig.rig.config import SimOptions
from rubber_rig.rig.sim.controller import SimController
from rubber_rig.rig.sim.plant import Sensor
from rubber_rig.session import run_program

from support.rig import FAST, expected_plant, poll_samples

WAVES = {
    'sine': '{waveform: sine, frequency: 8 Hz, amplitude: 0.5 mm, cycles: 4}',
    'triangle': '{waveform: triangle, frequency: 2 Hz, amplitude: 0.5 mm, cycles: 2}',
    'square': '{waveform: square, frequency: 2 Hz, amplitude: 0.5 mm, rate: 20 mm/s, cycles: 2}',
    'sweep_lin': '{waveform: sweep_lin, f_start: 2 Hz, f_end: 20 Hz, duration: 1 s, amplitude: 0.3 mm}',
    'sweep_log': '{waveform: sweep_log, f_start: 2 Hz, f_end: 20 Hz, duration: 1 s, amplitude: 0.3 mm}',
    'ramp_hold': '{waveform: ramp, target: -0.8 mm, rate: 5 mm/s}\n  - {waveform: hold, duration: 0.2 s}\n'
                 '  - {waveform: sine, frequency: 4 Hz, amplitude: 0.3 mm, cycles: 2}\n'
                 '  - {waveform: ramp, target: 0 mm, duration: 0.3 s}',
}


@pytest.mark.parametrize('wave', sorted(WAVES))
def test_every_waveform_through_driver_and_sim(wave):
    prog = Program.from_yaml_text(f'name: {wave}\nblocks:\n  - {WAVES[wave]}\n')
    r = run_program(prog, FAST)
    n = prog.n_samples(1000.0)
    assert r.completed, r.message
    assert r.final_status.frames_lost == 0 and r.final_status.frames_malformed == 0
    assert r.sequence[0] == 0 and np.all(np.diff(r.sequence) == 1) and r.sequence.size >= n
    # the controller applied exactly the program's setpoints (DBC resolution 0.1 um)
    np.testing.assert_allclose(r.setpoint[:n], prog.setpoints(1000.0), atol=0.6e-7)
    # measurement = second-order actuator + seed-000 specimen + sensor noise (0.2 um, 2 N) and resolution
    x, f = expected_plant(r)
    assert np.max(np.abs(r.displacement - x)) < 1.5e-6
    assert np.max(np.abs(r.force - f)) < 15.0
    assert np.std(r.force - f) == pytest.approx(2.0, rel=0.25)
    assert np.all(r.block_index[:n] >= 0)
    assert r.temperature.mean() == pytest.approx(20.0, abs=0.05)


def test_actuator_attenuates_at_high_frequency_and_amplitude_control_recovers_it():
    prog = Program.from_yaml_text('name: hf\nblocks:\n  - {waveform: sine, frequency: 40 Hz, amplitude: 0.5 mm, '
                                  'cycles: 16, taper_cycles: 2}\n')
    cfg = dict(FAST, limits={'velocity_max': 0.5})
    open_loop = run_program(prog, cfg).blocks[0]
    # second-order loop 80 Hz, zeta 0.8: |H(40 Hz)| = 1 / sqrt((1 - 0.25)^2 + (2 * 0.8 * 0.5)^2) = 0.9129
    assert open_loop.achieved_amplitude / 0.5e-3 == pytest.approx(1 / math.sqrt(0.75 ** 2 + 0.8 ** 2), rel=5e-3)
    closed = run_program(prog, cfg, amplitude_control=True)
    blk = closed.blocks[0]
    assert abs(blk.achieved_amplitude / 0.5e-3 - 1) < 0.01
    # measured cycle by cycle: within 1 % from the 5th steady cycle on (at 40 Hz the 50 ms lookahead of the
    # setpoint stream is two cycles of measurement latency, and a correction is blended over one cycle)
    x = closed.displacement[closed.block_index == 0]
    t = np.arange(x.size) / 1000.0
    amps = []
    for c in range(2 + 4, 2 + 16):
        sel = (t * 40 >= c) & (t * 40 < c + 1)
        w = 2 * np.pi * 40 * t[sel]
        coef = np.linalg.lstsq(np.column_stack([np.ones_like(w), np.sin(w), np.cos(w)]), x[sel], rcond=None)[0]
        amps.append(math.hypot(coef[1], coef[2]))
    assert np.max(np.abs(np.array(amps) / 0.5e-3 - 1)) < 0.01


def test_amplitude_control_with_preload_mean():
    prog = Program.from_yaml_text("""
name: pre
blocks:
  - {waveform: ramp, target: -1.1 mm, rate: 5 mm/s}
  - {name: pad, waveform: sine, frequency: 30 Hz, amplitude: 0.5 mm, cycles: 12, taper_cycles: 2}
""")
    r = run_program(prog, dict(FAST, limits={'velocity_max': 0.5}), amplitude_control=True)
    blk = r.blocks[1]
    assert abs(blk.achieved_amplitude / 0.5e-3 - 1) < 0.01
    assert blk.achieved_mean == pytest.approx(-1.1e-3, abs=5e-6)


def with_the_nodes_latency(run, sequence):
    """run_program's before_chunk: the runner sees each measured sample only once the setpoints `lead` beyond
    it have been generated, i.e. a measurement latency of the lookahead, which is what a streamed rig (the ROS
    nodes with lead_time = lookahead) has. Without it a fast run feeds the measurement as soon as the simulated
    rig has consumed the queue, so the amplitude loop sees at most one chunk of latency.
    """
    run.feed_on_arrival = False
    run.feed(sequence - run.session.lead)


def test_compensation_memory_reaches_the_target_from_the_second_block_with_the_nodes_lead():
    # 8 cycles per block, measurement seen 0.5 s after the setpoint (the excitation node's lead_time): a
    # block's own correction arrives only in its last cycles. A 60 Hz actuator (the low end of 60-100 Hz)
    # makes the attenuation at 14 Hz clearly more than 1 % (the default 80 Hz loop gives 0.9 %).
    prog = Program.from_yaml_text('name: asc\nblocks:\n' + ''.join(
        f'  - {{name: s{f}, waveform: sine, frequency: {f} Hz, amplitude: 0.5 mm, cycles: 8}}\n'
        for f in (8, 10, 12, 14)))
    cfg = dict(FAST, sim={'actuator_frequency': 60.0})
    # the node streams in 50-sample batches (1 kHz): bigger chunks would add latency on top of the lead
    with_memory = run_program(prog, cfg, amplitude_control=True, lookahead=0.5, chunk=50,
                              before_chunk=with_the_nodes_latency)
    per_block = run_program(prog, cfg, amplitude_control=True, lookahead=0.5, chunk=50,
                            before_chunk=with_the_nodes_latency, compensation_memory=False)
    assert with_memory.completed and per_block.completed
    err = [b.achieved_amplitude / b.target_amplitude - 1 for b in with_memory.blocks]
    assert all(b.cycles_measured == 8 for b in with_memory.blocks)
    assert all(abs(e) < 0.01 for e in err[1:]), err
    # without the memory: the first block of any run, and every block of the control run
    assert with_memory.blocks[0].achieved_amplitude == per_block.blocks[0].achieved_amplitude
    assert per_block.blocks[3].achieved_amplitude / 0.5e-3 - 1 < -0.01


def test_paced_and_fast_runs_are_identical():
    prog = Program.from_yaml_text('name: p\nblocks:\n  - {waveform: sine, frequency: 10 Hz, amplitude: 0.5 mm, '
                                  'cycles: 2, taper_cycles: 1}\n')
    fast = run_program(prog, FAST)
    # the whole program is queued at once (lookahead 0.5 s) and the wall-clock watchdog is lenient, so a
    # loaded machine cannot make the real-time simulator thread underrun or trip
    paced = run_program(prog, {'paced': True, 'watchdog_timeout': 1.0}, lookahead=0.5)
    n = prog.n_samples(1000.0)
    assert paced.completed and fast.completed
    # same waveform and physics, same seeded noise: identical samples (paced took real time)
    np.testing.assert_array_equal(paced.setpoint[:n], fast.setpoint[:n])
    np.testing.assert_array_equal(paced.displacement[:n], fast.displacement[:n])
    np.testing.assert_array_equal(paced.force[:n], fast.force[:n])
    assert paced.wall_time >= 0.9 * n / 1000.0


@pytest.mark.parametrize('rate, profile', [(10000.0, 'packed'), (1000.0, 'single')])
def test_block_ticks_equal_tick_by_tick(monkeypatch, rate, profile):
    """The controller's numpy block path gives the very samples of its per-sample path."""
    prog = Program.from_yaml_text('name: b\nblocks:\n  - {waveform: sine, frequency: 20 Hz, amplitude: 0.5 mm, '
                                  'cycles: 6, taper_cycles: 1}\n')
    cfg = dict(FAST, sample_rate=rate, profile=profile)
    blocks = run_program(prog, cfg)
    monkeypatch.setattr(SimController, 'MAX_BLOCK', 1)     # a block of one tick takes the per-sample path
    ticks = run_program(prog, cfg)
    n = prog.n_samples(rate)
    assert blocks.completed and ticks.completed and blocks.final_status.frames_lost == 0
    for name in ('setpoint', 'displacement', 'force'):
        np.testing.assert_array_equal(getattr(blocks, name)[:n], getattr(ticks, name)[:n])


def test_seed000_program_block_through_the_rig_reports_progress():
    full = load_program('dynamic_stiffness_grid')
    prog = Program(name='seed000_two', blocks=[full.blocks[4], full.blocks[16]])  # 4 Hz 0.5 mm, 5 Hz 1 mm
    seen = []
    r = run_program(prog, FAST, on_progress=seen.append)
    assert r.completed
    assert [b.name for b in r.blocks] == ['sine_0.5mm_4Hz', 'sine_1mm_5Hz']
    for b in r.blocks:
        assert b.cycles_measured == 8 and abs(b.achieved_amplitude / b.target_amplitude - 1) < 0.01
    assert seen and seen[-1].block_index == 1 and {p.block_index for p in seen} == {0, 1}
    # seed-000 SARJ at 20 degC: about 13-15 kN at 1 mm
    f1 = r.force[r.block_index == 1]
    assert 12e3 < np.max(np.abs(f1)) < 17e3


def test_driver_status_and_sample_blocks_on_open_rig():
    with open_rig({'paced': False, 'sim': {'temperature': 20.0}}) as rig:
        assert rig.wait_ready(5.0)
        drv = rig.driver
        st = drv.status
        assert st.state == 'idle' and st.faults == 0
        x = 0.2e-3 * np.sin(np.linspace(0, np.pi, 200)) ** 2
        assert drv.queue_setpoints(0, x)
        blocks = []
        n = poll_samples(drv, blocks, 200, 20000)
        assert n == 200 and blocks[0].first_sequence == 0 and blocks[0].sample_period == 1e-3
        seq = np.concatenate([b.sequence for b in blocks])
        np.testing.assert_array_equal(seq, np.arange(200))
        np.testing.assert_allclose(np.concatenate([b.setpoint for b in blocks]), x, atol=0.6e-7)
        st = drv.status
        assert st.samples_received == 200 and st.frames_lost == 0 and st.setpoints_sent == 200
        assert st.temperature == pytest.approx(20.0, abs=0.1)


def test_specimen_parameter_set_and_temperature_are_selectable():
    prog = Program.from_yaml_text('name: k\nblocks:\n  - {waveform: sine, frequency: 2 Hz, amplitude: 0.5 mm, '
                                  'cycles: 3}\n')
    warm = run_program(prog, FAST)
    cold = run_program(prog, dict(FAST, sim={'specimen': {'model': 'seed000', 'temperature': -40.0},
                                             'temperature': -40.0}))
    lin = run_program(prog, dict(FAST, sim={'specimen': {'model': 'linear', 'stiffness': 5e6, 'damping': 0.0}}))
    assert np.max(np.abs(cold.force)) > 1.1 * np.max(np.abs(warm.force))   # stiffer when cold (seed 000 Table 1)
    assert cold.temperature.mean() == pytest.approx(-40.0, abs=0.05)
    assert np.max(np.abs(lin.force)) == pytest.approx(5e6 * 0.5e-3, rel=0.01)
    opt = SimOptions(specimen={'model': 'seed000', 'temperature': -40.0})
    _, f = expected_plant(cold, opt)
    assert np.max(np.abs(cold.force - f)) < 15.0


def test_config_from_dict_round_trip():
    cfg = RigConfig.from_dict({'backend': 'sim', 'sample_rate': 2000.0, 'paced': False,
                               'limits': {'force_max': 30e3}, 'sim': {'faults': [{'type': 'drop'}]}})
    again = RigConfig.from_dict(cfg.to_dict())
    assert again == cfg and again.limits.force_max == 30e3 and again.sim.faults[0].type == 'drop'


def test_new_stream_after_a_pause_is_bridged_by_holding():
    with open_rig({'paced': False}) as rig:
        assert rig.wait_ready(5.0)
        drv = rig.driver
        ramp = 0.3e-3 * np.sin(np.linspace(0, np.pi / 2, 300)) ** 2
        assert drv.queue_setpoints(0, ramp)
        got = []
        poll_samples(drv, got, 300, 1000)
        # the next program starts 100 samples later: the controller holds 0.3 mm in between, no step
        assert drv.queue_setpoints(300, np.full(100, 0.3e-3)) and drv.queue_setpoints(400, np.full(50, 0.3e-3))
        poll_samples(drv, got, 450, 1000)
        seq = np.concatenate([g.sequence for g in got])
        u = np.concatenate([g.setpoint for g in got])
        np.testing.assert_array_equal(seq, np.arange(450))
        assert np.max(np.abs(np.diff(u))) < 5e-6 and drv.status.frames_lost == 0


def test_sensor_offset_resolution_and_noise_are_applied():
    prog = Program.from_yaml_text('name: s\nblocks:\n  - {waveform: sine, frequency: 5 Hz, amplitude: 0.5 mm, '
                                  'cycles: 2}\n')
    opt = {'displacement_offset': 20e-6, 'displacement_resolution': 1e-6, 'displacement_noise': 0.0,
           'force_offset': -50.0, 'force_resolution': 1.0, 'force_noise': 5.0,
           'specimen': {'model': 'linear', 'stiffness': 1.3e7, 'damping': 0.0}}
    r = run_program(prog, dict(FAST, sim=opt))
    assert r.completed
    x, f = expected_plant(r, SimOptions(**{k: v for k, v in opt.items()}))
    steps = r.displacement / 1e-6
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)                 # 1 um resolution
    np.testing.assert_allclose(r.displacement, x + 20e-6, atol=0.5e-6 + 1e-9)     # offset, no noise
    np.testing.assert_allclose(r.force / 1.0, np.round(r.force), atol=1e-6)      # 1 N resolution
    assert np.mean(r.force - f) == pytest.approx(-50.0, abs=0.5)
    assert np.std(r.force - f) == pytest.approx(5.0, rel=0.1)


def test_load_cell_zero_drift_grows_with_the_run_time():
    # a load cell warming up: the offset grows by force_drift per second of the run, read one by one or in
    # blocks alike
    prog = Program.from_yaml_text('name: s\nblocks:\n  - {waveform: sine, frequency: 5 Hz, amplitude: 0.5 mm, '
                                  'cycles: 20}\n')
    opt = {'force_drift': 10.0, 'force_noise': 0.0, 'force_resolution': 1e-3,
           'specimen': {'model': 'linear', 'stiffness': 1.3e7, 'damping': 0.0}}
    r = run_program(prog, dict(FAST, sim=opt))
    assert r.completed
    _, f = expected_plant(r, SimOptions(**{k: v for k, v in opt.items() if k != 'force_drift'}))
    t = np.arange(r.force.size) / 1000.0
    slope, offset = np.polyfit(t, r.force - f, 1)
    assert slope == pytest.approx(10.0, rel=1e-3) and abs(offset) < 0.05
    one = Sensor(0.0, 1.0, 1e-6, np.random.default_rng(0), drift=0.5)
    many = Sensor(0.0, 1.0, 1e-6, np.random.default_rng(0), drift=0.5)
    singles = [one.read(0.0) for _ in range(5)]
    np.testing.assert_allclose(singles, [1.0, 1.5, 2.0, 2.5, 3.0])
    np.testing.assert_allclose(np.concatenate([many.read_many(np.zeros(2)), many.read_many(np.zeros(3))]), singles)


def test_rig_config_settings_describe_every_parameter_once():
    """RigConfig's fields carry their parameter description (rubber_rig.settings): names are unique, defaults
    are the dataclass defaults, and every numeric default lies inside its declared range."""
    from rubber_rig.rig.config import RigConfig
    from rubber_rig.settings import nest, settings_of
    settings = settings_of(RigConfig)
    names = [s.name for s in settings]
    assert len(names) == len(set(names))
    assert {'can.bitrate', 'limits.velocity_max', 'sim.force_noise', 'sim.faults', 'stream_timeout'} <= set(names)
    for s in settings:
        assert s.doc, s.name
        if s.range is not None:
            assert s.range[0] <= s.default <= s.range[1], s.name
    # the parameter defaults, read back through the settings, give the dataclass defaults
    cfg = RigConfig.from_dict(nest({s.path: s.value(s.default) for s in settings}))
    assert cfg == RigConfig()


def test_tighter_host_limits_refuse_the_setpoints_already_queued_and_min_above_max_is_discarded():
    """docs/protocol.md "Envelope": HostLimits that tighten while setpoints are queued bind those too (flush, ramp
    to rest, displacement_limit); a HostLimits with min >= max is discarded whole (counted), the limits unchanged.
    """
    import can

    from rubber_rig.rig.can.frames import SampleFrames
    from rubber_rig.rig.can.protocol import FAULT_DISPLACEMENT_LIMIT, Protocol
    proto = Protocol()
    with can.Bus(interface='virtual', channel='sim_tighter_limits', receive_own_messages=False) as sim_bus, \
            can.Bus(interface='virtual', channel='sim_tighter_limits', receive_own_messages=False) as bus:
        rig = SimController(sim_bus, 1000.0, SimOptions(), paced=False)
        frames = SampleFrames('packed', proto.db, 1000.0)

        def receive():      # the receive side alone (no tick): the setpoints stay queued
            rig.receiver.receive_all()
        bus.send(proto.encode('HostStreamStart', {'HS_FirstSequence': 0}))
        for msg in frames.encode_setpoints(0, [2e-6 * k for k in range(200)]):
            bus.send(msg)
        bus.send(proto.encode('HostLimits', {'HL_DisplacementMin': 1e-3, 'HL_DisplacementMax': -1e-3,
                                             'HL_Deceleration': 100}))
        receive()
        assert rig.state == 'running' and rig.counters['frames_bad'] == 1
        assert (rig.lower, rig.upper) == (-math.inf, math.inf)
        queued_max = max(rig.buffer.values())
        assert queued_max > 1e-4
        bus.send(proto.encode('HostLimits', {'HL_DisplacementMin': -1e-3, 'HL_DisplacementMax': 1e-4,
                                             'HL_Deceleration': 100}))
        receive()
        assert rig.fault_bits == FAULT_DISPLACEMENT_LIMIT and not rig.buffer
        assert rig.state in ('ramping_down', 'fault')
