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

"""Soak: the four node processes on a paced 1 kHz simulated rig, programs back to back, the system churning.

For --minutes (30), while programs run back to back:

- short-lived client processes join and leave every --client-every s (half of them killed without a goodbye, so
  their DDS participants expire by lease: the pattern that once deadlocked element_model inside Fast DDS);
- a second suite (namespace /rig2, same domain, niced) runs for 60 s every --second-every s;
- one node of the suite is SIGKILLed and restarted every --kill-every s, in turn element_model, recorder,
  excitation, rig_driver;
- element_model is frozen (SIGSTOP for 3 s) every --freeze-every s: a stuck node, to time its detection.

    .venv/bin/python benchmarks/bench_soak.py                 # the 30-minute run
    .venv/bin/python benchmarks/bench_soak.py --minutes 3     # a quick look

Reported: programs run and how they ended (a fault is expected when the excitation or rig_driver was killed
during the program, otherwise false), silences seen on the heartbeats (expected: kills and freezes; any other is
a freeze nobody caused) with the time to detection, RSS growth of each node (per process lifetime, MB/h), and the
loss ledger from the recorder's close records, `info` (load_recording), `recover` and the operator's own view.
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
import argparse
import json
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from rubber_rig.nodes.heartbeat import Peers
from rubber_rig.recording import load_recording
from rubber_rig.recording.errors import RecordingError
from rubber_rig.recording.recover import recover
from rubber_rig.testing.operator import Operator
from rubber_rig.testing.processes import NODES, SuiteProcesses

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'rig_sim.yaml'
NS, NS2 = '/soak', '/rig2'
PROGRAMS = [
    'name: soak_sine\nblocks:\n  - {name: s, waveform: sine, frequency: 5 Hz, amplitude: 1 mm, cycles: 60}\n',
    'name: soak_mixed\nblocks:\n  - {name: t, waveform: triangle, frequency: 1 Hz, amplitude: 0.5 mm, cycles: 4}\n'
    '  - {name: h, waveform: hold, duration: 2 s}\n'
    '  - {name: s, waveform: sine, frequency: 10 Hz, amplitude: 0.3 mm, cycles: 40}\n',
]
CLIENT = """
import os, sys, time, rclpy
from rubber_rig.dds import configure_dds
configure_dds()
rclpy.init()
n = rclpy.create_node('soak_client_%d' % os.getpid(), namespace='{ns}')
t0 = time.time()
while time.time() - t0 < 1.5:
    rclpy.spin_once(n, timeout_sec=0.1)
n.get_topic_names_and_types()
if int(sys.argv[1]) % 2:
    os._exit(0)                      # no goodbye: the participant expires by lease
n.destroy_node()
rclpy.shutdown()
"""


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


class Soak:
    def __init__(self, args, work: Path):
        self.args, self.work = args, work
        self.t0 = time.monotonic()
        self.procs = SuiteProcesses(CONFIG, NS, args.domain_id, work / 'logs',
                                    {'recorder': {'output_dir': str(work / 'rec')}})
        self.log: list[dict] = []            # what was done to the system, when
        self.silences: list[dict] = []       # heartbeat silences seen by the operator
        self.rss: dict[tuple[str, int], list[tuple[float, float]]] = {}
        self.programs: list[dict] = []
        self.stop = threading.Event()
        self.clients = 0

    def now(self) -> float:
        return time.monotonic() - self.t0

    def note(self, kind: str, **kw):
        self.log.append(dict(kind=kind, t=self.now(), **kw))
        print(f'[{self.now():7.1f} s] {kind} {kw}', flush=True)

    # -- the churn ----------------------------------------------------------------------------------------------
    def churn(self):
        a = self.args
        nxt = {'client': a.client_every, 'second': a.second_every, 'kill': a.kill_every, 'freeze': a.freeze_every,
               'rss': 0.0}
        order = ['element_model', 'recorder', 'excitation', 'rig_driver']
        kills = 0
        second = None
        while not self.stop.wait(0.2):
            t = self.now()
            if t >= nxt['rss']:
                nxt['rss'] = t + 10.0
                for node in NODES:
                    p = self.procs.procs.get(node)
                    if p is not None and p.poll() is None:
                        mb = rss_mb(p.pid)
                        if mb is not None:
                            self.rss.setdefault((node, p.pid), []).append((t, mb))
            if t >= nxt['client']:
                nxt['client'] = t + a.client_every
                self.clients += 1
                subprocess.Popen([sys.executable, '-c', CLIENT.replace('{ns}', NS), str(self.clients)],
                                 env=self.procs.env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            if t >= nxt['second'] and second is None:
                second = SuiteProcesses(CONFIG, NS2, a.domain_id, self.work / 'logs2',
                                        {'recorder': {'output_dir': str(self.work / 'rec2')}}, niceness=10)
                second.start_all()
                second_until = t + 60.0
                self.note('second suite up')
            if second is not None and t >= second_until:
                second.stop_all()
                second = None
                nxt['second'] = t + a.second_every
                self.note('second suite down')
            if t >= nxt['kill']:
                nxt['kill'] = t + a.kill_every
                node = order[kills % len(order)]
                kills += 1
                self.note('kill', node=node)
                self.procs.kill(node, signal.SIGKILL)
                time.sleep(1.0)
                self.procs.start(node)
                ok = self.procs.wait_started(node, 30.0)
                self.note('restarted', node=node, ok=ok)
            if t >= nxt['freeze']:
                nxt['freeze'] = t + a.freeze_every
                p = self.procs.procs['element_model']
                self.note('freeze', node='element_model')
                os.kill(p.pid, signal.SIGSTOP)
                time.sleep(3.0)
                os.kill(p.pid, signal.SIGCONT)
                self.note('thaw', node='element_model')
        if second is not None:
            second.stop_all()

    def watch(self, peers: Peers):
        """Every silence on the heartbeats of the suite's nodes: when it was first seen and how long it lasted."""
        open_ = {}
        names = {f'{NS}/{n}' for n in NODES}
        while not self.stop.wait(0.05):
            quiet = peers.silent(names)
            t = self.now()
            for n in quiet:
                if n not in open_:
                    open_[n] = {'node': n, 'seen': t, 'silent_for_at_detection': quiet[n]}
            for n in set(open_) - set(quiet):
                s = open_.pop(n)
                s['end'] = t
                self.silences.append(s)

    # -- the programs -------------------------------------------------------------------------------------------
    def run(self):
        a = self.args
        self.procs.start_all()
        op = Operator(NS, a.domain_id, name='soak_operator')
        peers = Peers(op.node)
        threads = [threading.Thread(target=self.churn, daemon=True),
                   threading.Thread(target=self.watch, args=(peers,), daemon=True)]
        try:
            if not op.wait_ready(60.0):
                raise SystemExit('the suite did not come up')
            for th in threads:
                th.start()
            k = 0
            while self.now() < a.minutes * 60:
                text = PROGRAMS[k % len(PROGRAMS)]
                k += 1
                start = self.now()
                handle = op.send_goal(text, timeout=20.0)
                if handle is None or not handle.accepted:
                    self.programs.append({'t': start, 'end': self.now(), 'outcome': 'not accepted',
                                          'message': 'no answer' if handle is None else 'refused'})
                    time.sleep(1.0)
                    op.wait_ready(20.0)
                    continue
                result = op.result(handle, 40.0)
                self.programs.append({'t': start, 'end': self.now(), 'outcome': 'ok' if result and result.success
                                      else 'failed', 'message': result.message if result else 'no result in 40 s'})
                if not (result and result.success):
                    print(f'[{self.now():7.1f} s] program ended: {self.programs[-1]["message"]}', flush=True)
                    for _ in range(5):      # acknowledge a fault as an operator would
                        if op.status is not None and op.status.faults:
                            op.trigger(f'{NS}/rig_driver/reset')
                        if op.wait_ready(5.0):
                            break
        finally:
            self.stop.set()
            for th in threads:
                th.join(timeout=90.0)
            self.op_view = operator_view(op)
            op.close()
            self.procs.stop_all()
        return self.report()

    # -- the figures --------------------------------------------------------------------------------------------
    def classify(self, p: dict) -> str:
        if p['outcome'] == 'ok':
            return 'completed'
        window = [e for e in self.log if e['kind'] in ('kill', 'restarted') and p['t'] - 2.0 <= e['t'] <= p['end']]
        if any(e.get('node') in ('excitation', 'rig_driver') for e in window):
            return 'expected fault'
        return 'false fault'

    def cause(self, s: dict) -> dict | None:
        """The latest kill or freeze that explains a silence (the silence was first seen within 40 s after it)."""
        for e in reversed(self.log):
            if e['kind'] in ('kill', 'freeze') and f'{NS}/{e["node"]}' == s['node'] \
                    and e['t'] - 0.5 <= s['seen'] <= e['t'] + 40.0:
                return e
        return None

    def expected_silence(self, s: dict) -> str:
        e = self.cause(s)
        return e['kind'] if e else ''

    def ledger(self) -> dict:
        info = recorder = recovered = 0
        files = truncated = refused = 0
        for d in sorted(p for p in (self.work / 'rec').iterdir() if p.is_dir()):
            try:
                rec = load_recording(d, allow_truncated=True)
            except RecordingError as exc:
                print(f'{d}: {exc}')
                refused += 1
                continue
            info += rec.samples_lost
            recorder += sum(int(c.get('samples_lost', 0)) for c in rec.closing)
            for f in sorted(d.glob('*.mcap')):
                files += 1
                try:
                    load_recording(f)
                    recovered += load_recording(f).samples_lost
                except RecordingError:
                    truncated += 1
                    out = self.work / 'recovered' / f.name
                    out.parent.mkdir(exist_ok=True)
                    recover(f, out)
                    recovered += load_recording(out).samples_lost
        return {'files': files, 'truncated_files': truncated, 'refused': refused, 'info': info,
                'recorder_close_records': recorder, 'recover': recovered, **self.op_view}

    def report(self) -> dict:
        outcomes = {}
        for p in self.programs:
            c = self.classify(p)
            outcomes[c] = outcomes.get(c, 0) + 1
            if c == 'false fault':
                print(f'false fault at {p["t"]:.0f} s: {p["message"]}')

        # several nodes silent at once (within 0.2 s): the observer (this process) stalled, not the nodes
        def together(s):
            return sum(abs(o['seen'] - s['seen']) <= 0.2 for o in self.silences) >= 2
        single = [s for s in self.silences if not together(s)]
        caused = [s for s in single if self.expected_silence(s)]
        freezes = [s for s in single if self.expected_silence(s) == 'freeze']
        spontaneous = [s for s in single if not self.expected_silence(s)]
        stalled = sorted({round(s['seen'], 1) for s in self.silences if together(s)})
        observer = [t for i, t in enumerate(stalled) if i == 0 or t - stalled[i - 1] > 0.5]
        detect = [s['seen'] - self.cause(s)['t'] for s in freezes]
        growth = {}
        for (node, _pid), pts in self.rss.items():
            if len(pts) >= 3 and pts[-1][0] - pts[0][0] >= 60:
                rate = (pts[-1][1] - pts[0][1]) / ((pts[-1][0] - pts[0][0]) / 3600)
                growth.setdefault(node, []).append((round(pts[0][1], 1), round(pts[-1][1], 1),
                                                    round((pts[-1][0] - pts[0][0]) / 60, 1), round(rate, 1)))
        return {'minutes': self.args.minutes, 'programs': len(self.programs), 'outcomes': outcomes,
                'kills': sum(e['kind'] == 'kill' for e in self.log), 'clients': self.clients,
                'second_suite_runs': sum(e['kind'] == 'second suite up' for e in self.log),
                'silences_caused': len(caused), 'silences_unexplained': spontaneous,
                'observer_stalls': len(observer),
                'freezes': len(freezes), 'freeze_detection_s': [round(d, 2) for d in detect],
                'rss': growth, 'loss': self.ledger()}


def operator_view(op) -> dict:
    """What the operator received: samples the driver reported lost on the bus (frames_lost of the batches) and the
    samples missing between its batches (lost, or the rig idle between programs: it cannot tell).
    """
    with op.lock:
        batches = list(op.batches)
    bus = sum(int(b.frames_lost) for b in batches)
    missing, expected = 0, None
    for b in batches:
        if expected is not None and b.first_sequence > expected:
            missing += b.first_sequence - expected
        expected = b.first_sequence + len(b.setpoint)
    return {'operator_frames_lost': bus, 'operator_batches': len(batches), 'operator_missing_or_idle': missing}


def markdown(r: dict) -> str:
    o = r['outcomes']
    lines = ['| figure | value |', '|---|---|',
             f"| duration | {r['minutes']} min at 1 kHz (paced) |",
             f"| programs run | {r['programs']} ({o.get('completed', 0)} completed, {o.get('expected fault', 0)} "
             f"expected faults, {o.get('false fault', 0)} false faults, {o.get('not accepted', 0)} not accepted) |",
             f"| churn | {r['kills']} node kills, {r['clients']} short-lived clients, {r['second_suite_runs']} "
             'second-suite runs |',
             f"| silences on the heartbeats | {r['silences_caused']} caused (kills, freezes), "
             f"{len(r['silences_unexplained'])} unexplained, {r['observer_stalls']} observer stalls (every node at "
             'once: this process stalled) |',
             f"| freezes (SIGSTOP 3 s) detected | {r['freezes']}, after {r['freeze_detection_s']} s |"]
    for node, rows in sorted(r['rss'].items()):
        text = '; '.join(f'{a}->{b} MB in {m} min ({g:+} MB/h)' for a, b, m, g in rows)
        lines.append(f'| RSS {node} | {text} |')
    loss = r['loss']
    lines.append(f"| loss ledger [samples] | recorder close records {loss['recorder_close_records']}, info "
                 f"{loss['info']}, recover {loss['recover']} ({loss['files']} files, {loss['truncated_files']} "
                 f"truncated by kills, {loss['refused']} refused); operator: bus loss reported in its batches "
                 f"{loss['operator_frames_lost']} |")
    return '\n'.join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--minutes', type=float, default=30.0)
    parser.add_argument('--client-every', type=float, default=15.0, help='[s] a short-lived client process')
    parser.add_argument('--second-every', type=float, default=300.0, help='[s] a second suite for 60 s')
    parser.add_argument('--kill-every', type=float, default=180.0, help='[s] SIGKILL and restart one node')
    parser.add_argument('--freeze-every', type=float, default=400.0, help='[s] SIGSTOP element_model for 3 s')
    parser.add_argument('--domain-id', type=int, default=120 + os.getpid() % 20)
    parser.add_argument('--json', help='also write the figures to this JSON file')
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix='soak_') as tmp:
        soak = Soak(args, Path(tmp))
        try:
            r = soak.run()
        finally:                          # the raw record, whatever the report makes of it
            raw = {'log': soak.log, 'programs': soak.programs, 'silences': soak.silences,
                   'rss': {f'{n}:{pid}': pts for (n, pid), pts in soak.rss.items()}}
            Path(args.json or 'soak.json').with_suffix('.raw.json').write_text(json.dumps(raw, default=str))
    print(markdown(r))
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1, default=str))
    return 0 if not r['outcomes'].get('false fault') and not r['silences_unexplained'] else 1


if __name__ == '__main__':
    sys.exit(main())
