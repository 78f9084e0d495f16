"""run_program: a ROS-free runner of a test program on a rig (simulated or real), returning numpy arrays."""
import time
from dataclasses import dataclass
from typing import Callable, List, Optional

import numpy as np

from ..excitation.program import Program, load_program
from ..excitation.runner import BlockResult, ProgramRunner
from .can.driver import DriverStatus
from .config import RigConfig
from .session import open_rig


@dataclass
class RunResult:
    """Everything measured in a run, one entry per received sample (SI units).

    time = sequence / sample_rate [s]; setpoint is the command the controller applied; block_index is the
    program block that generated the sample (-1 for the abort or hold ramps); status is the controller fault
    mask. `blocks` are the runner's block summaries; `completed` is False after an abort or fault.
    """

    program: str
    sample_rate: float
    sequence: np.ndarray
    time: np.ndarray
    setpoint: np.ndarray
    displacement: np.ndarray
    force: np.ndarray
    temperature: np.ndarray
    status: np.ndarray
    block_index: np.ndarray
    blocks: List[BlockResult]
    completed: bool
    message: str
    final_status: DriverStatus
    wall_time: float


def run_program(program, config, on_progress: Optional[Callable] = None, amplitude_control: bool = False,
                lookahead: float = None, rig=None, progress_period: float = 0.1,
                abort_after: float = None, compensation_memory: bool = True,
                lead_latency: bool = False) -> RunResult:
    """Run `program` (Program, YAML path or shipped name) on the rig of `config` (RigConfig or mapping).

    The program is validated against the limits before the rig is opened, so nothing is sent on error.
    Setpoints are streamed `lookahead` seconds ahead of the measurement (default 0.1 s paced, 0.05 s fast).
    on_progress(Progress) is called every progress_period seconds of samples. abort_after [s of samples]:
    abort the program there (tests of the abort path). An open `rig` may be passed in (not closed here).
    compensation_memory: see ProgramRunner (with amplitude_control: blocks start from what earlier blocks
    learned).

    lead_latency: the runner sees each measured sample only once the setpoints `lookahead` beyond it have been
    generated (in chunks of at most 50 ms) - the measurement latency the excitation node has with lead_time =
    lookahead. Without it a fast run feeds the measurement as soon as the simulated rig has consumed the
    queue, so the amplitude loop sees at most one chunk of latency; a paced rig consumes in real time and has
    about `lookahead` of latency anyway. It changes nothing open loop.
    """
    cfg = RigConfig.from_dict(config)
    if not isinstance(program, Program):
        program = load_program(program)
    fs = cfg.sample_rate
    runner = ProgramRunner(program, fs, cfg.limits, amplitude_control=amplitude_control,   # checks limits
                           compensation_memory=compensation_memory)
    own = rig is None
    rig = open_rig(cfg) if own else rig
    t_wall = time.monotonic()
    try:
        if not rig.wait_ready(10.0):
            raise RuntimeError('the rig controller did not announce itself within 10 s')
        return _loop(program, cfg, rig.driver, runner, on_progress, lookahead, progress_period, abort_after,
                     t_wall, lead_latency)
    finally:
        if own:
            rig.close()


def _loop(program, cfg, drv, runner, on_progress, lookahead, progress_period, abort_after, t_wall,
          lead_latency=False):
    fs = cfg.sample_rate
    if lookahead is None:
        lookahead = 0.1 if cfg.paced else 0.05
    ahead = max(2, int(round(lookahead * fs)))
    # paced: 10 ms chunks keep the stream smooth; fast: half the lookahead amortises per-chunk overhead
    chunk = max(1, min(ahead // 2, int(round(0.01 * fs)))) if cfg.paced else max(1, ahead // 2)
    if lead_latency:   # the node streams in 50-sample batches; big chunks would add latency on top of the lead
        chunk = max(1, min(chunk, int(round(0.05 * fs))))
    grant = drv.open_stream('run_program')        # StreamRefused (a ValueError) says why not
    first = grant.first_sequence
    runner.sequence = first
    queued = first
    block_of = []                      # program block per queued setpoint
    queued_x = []                      # the queued setpoints [m]
    got = []                           # SampleBlocks
    fed = 0                            # got[:fed] have been fed to the runner

    def feed(upto):
        # measured samples below sequence `upto` to the runner (a SampleBlock only once it is whole below)
        nonlocal fed
        while fed < len(got) and got[fed].first_sequence + len(got[fed]) <= upto:
            runner.feed_measurement(got[fed].first_sequence, got[fed].displacement)
            fed += 1

    received = first
    next_progress = first
    abort_seq = None if abort_after is None else first + int(round(abort_after * fs))
    stopped, message, quiet_since = False, '', None
    while True:
        # stream ahead of the measurement; in fast mode this is what lets the simulated rig advance
        # the controller's own last consumed sequence also counts: a burst of lost feedback frames must not
        # starve a fast-mode rig of setpoints (it would never send the frame that reveals the gap)
        done = max(received, drv.controller_sequence + 1)
        while not stopped and not runner.finished and queued - done < ahead:
            if abort_seq is not None and queued >= abort_seq and not runner.aborted:
                runner.abort('abort_after')
            if lead_latency:
                feed(queued - ahead)
            x = runner.next_setpoints(chunk)
            if not drv.queue_setpoints(queued, x, grant.stream_id):
                stopped = True
                break
            block_of.append(runner.last_block_index)
            queued_x.append(x)
            queued += chunk
            if runner.finished:
                drv.end_stream(grant.stream_id)   # running dry after this is the program's end, not a loss
        progressed = False
        blk = drv.poll()
        while blk is not None:
            got.append(blk)
            if not lead_latency:
                feed(np.inf)
            received = blk.first_sequence + len(blk)
            progressed = True
            blk = drv.poll()
        if lead_latency and (stopped or runner.finished):
            feed(np.inf)               # nothing more is generated: the rest of the measurement is due
        if on_progress is not None and received >= next_progress:
            on_progress(runner.progress)
            next_progress = received + max(1, int(progress_period * fs))
        st = drv.status
        if st.faults and not stopped:
            stopped = True
        if stopped and not message:
            message = '; '.join(st.fault_messages) or 'stopped'
            runner.abort(message)
        if stopped:
            # wait for the controller's safe ramp to finish and its samples to arrive (a silent controller
            # never reports idle: then a second without samples ends the wait)
            if not progressed:
                quiet_since = quiet_since or time.monotonic()
                quiet = time.monotonic() - quiet_since
                if quiet > 1.0 or quiet > 0.2 and st.controller_state in ('idle', 'fault'):
                    break
            else:
                quiet_since = None
        elif runner.finished and received >= queued:
            break
        elif runner.finished and not progressed and st.controller_sequence >= queued - 1:
            quiet_since = quiet_since or time.monotonic()
            if time.monotonic() - quiet_since > 0.5:   # the last samples were lost on the bus
                break
        if not progressed:
            # paced: the rig produces 1 sample per period anyway; sleeping leaves the CPU (and the GIL) to it
            time.sleep(0.002 if cfg.paced else 0.0001)
    feed(np.inf)
    return _result(program, cfg, drv, runner, got, block_of, queued_x, first, message, t_wall)


def _result(program, cfg, drv, runner, got, block_of, queued_x, first, message, t_wall):
    fs = cfg.sample_rate
    cat = (lambda name: np.concatenate([getattr(b, name) for b in got])) if got else (lambda name: np.empty(0))
    seq = np.concatenate([b.sequence for b in got]) if got else np.empty(0, dtype=np.int64)
    rep = lambda attr, dtype: (np.concatenate([np.full(len(b), getattr(b, attr), dtype=dtype) for b in got])  # noqa
                               if got else np.empty(0, dtype=dtype))
    blocks_all = np.concatenate(block_of) if block_of else np.empty(0, dtype=np.int32)
    idx = seq - first
    inside = (idx >= 0) & (idx < blocks_all.size)
    block_index = np.full(seq.size, -1, dtype=np.int32)
    block_index[inside] = blocks_all[idx[inside]]
    setpoint = cat('setpoint')
    if message and got:
        # after a fault the controller flushed the queue and ramps on its own: from the first sample whose applied
        # command is not the queued one (beyond the 0.1 um frame resolution) the samples belong to no block
        sent = np.concatenate(queued_x)
        off = np.nonzero(inside & (np.abs(setpoint - sent[np.where(inside, idx, 0)]) > 1.5e-7))[0]
        if off.size:
            block_index[off[0]:] = -1
    st = drv.status
    completed = runner.finished and not runner.aborted and not st.faults
    return RunResult(program.name, fs, seq, seq / fs, setpoint, cat('displacement'), cat('force'),
                     rep('temperature', float), rep('status_flags', np.uint32), block_index,
                     runner.block_summaries, completed, message or ('completed' if completed else runner.abort_reason),
                     st, time.monotonic() - t_wall)
