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

"""Run the benchmarks and write what they measured to docs/benchmarks/ (the README links there, it copies nothing).

    make benchmarks                                   # every benchmark, one after the other (several hours)
    make benchmarks ARGS="--only models,rig,checks"   # some of them
    .venv/bin/python benchmarks/run_all.py --list     # what there is, how long each takes

Each benchmark runs as its own process with the arguments listed in BENCHMARKS (the runs the README describes),
one at a time: the timing figures need the machine to themselves (2 cores here). For each, two files:

- ``docs/benchmarks/<name>.md``: how it was run (command, commit, date, machine, wall time, exit status), then the
  benchmark's own output (its Markdown tables) verbatim;
- ``docs/benchmarks/<name>.json``: the same facts and, for the benchmarks that write one (``--json``), their
  machine-readable results.

``docs/benchmarks/README.md`` lists every file with its date and commit, so a stale figure shows its age. A
benchmark that fails still gets its files (exit status and output say what happened); the runner then exits 1.
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); the benchmarks inherit it

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / 'docs' / 'benchmarks'


@dataclass(frozen=True)
class Benchmark:
    """One benchmark run: script in benchmarks/, its arguments, what it measures, about how long it takes [min]."""

    name: str
    script: str
    args: tuple
    what: str
    minutes: float
    json_arg: str = ''          # the script's option that writes its results as JSON ('' = none)


BENCHMARKS = (
    Benchmark('checks', 'bench_checks.py', (), 'pre-start program checks of the longest programs', 0.5),
    Benchmark('seed004_pad', 'bench_seed004_pad.py', (), 'the seed-004 pad specimen against Table 2', 0.2),
    Benchmark('models', 'bench_models.py', (), 'element models: cost per sample, throughput, fractional accuracy',
              3),
    Benchmark('rig', 'bench_rig.py', ('--paced', '10000'), 'CAN bus load per profile, cost of the frame path, a '
              'paced 10 kHz run', 6),
    Benchmark('recording', 'bench_recording.py', (), 'MCAP write throughput, file size, recorder node CPU', 3),
    Benchmark('fitting', 'bench_fitting.py', (), 'rubber-rig fit on seed-000 grid recordings at 4 temperatures', 15),
    Benchmark('detectors', 'bench_detectors.py', (), 'detection delay and false trips of the detectors', 10,
              '--json'),
    Benchmark('detector_causes', 'bench_detector_causes.py', (), 'what each detector event is put down to: specimen, '
              'model mismatch, load-cell faults, fixture slip; delays and false trips', 10),
    Benchmark('scenario', 'bench_scenario.py', ('--lead',), 'the scenario harness on simulated time: speed, scenarios, '
              'the lead_time table', 2),
    Benchmark('safety', 'bench_safety.py', (), 'abort latency per path, stopping distance, false trips', 40,
              '--json'),
    Benchmark('signing', 'bench_signing.py', (), 'authenticated commands and samples: µs to sign and verify a batch, '
              'CPU share at 1 and 10 kHz', 0.2, '--json'),
    Benchmark('suite', 'bench_suite.py', ('--rate', '1000', '--duration', '600'), 'the node suite at 1 kHz for '
              '10 min: loss, latency, CPU', 12, '--json'),
    Benchmark('suite_rates', 'bench_suite.py', ('--rate', '10000', '--duration', '60'), 'the node suite at 10 kHz '
              '(packed CAN FD)', 3, '--json'),
    Benchmark('suite_processes', 'bench_suite.py', ('--processes', '--spawn-sim', '--rate', '1000', '--duration',
              '600'), 'each node a process, the sim rig apart, 1 kHz for 10 min: loss, latency, CPU per node', 12,
              '--json'),
    Benchmark('suite_processes_busy', 'busy_load.py', ('--loops', '1', '--', '.venv/bin/python',
              'benchmarks/bench_suite.py', '--processes', '--spawn-sim', '--rate', '1000', '--duration', '600'),
              'as suite_processes, beside one busy-loop process (a compiler, a browser tab): loss, latency, CPU', 12,
              '--json'),
    Benchmark('suite_processes_10k', 'bench_suite.py', ('--processes', '--rate', '10000', '--duration', '600'),
              'each node a process at 10 kHz (packed CAN FD) for 10 min: loss, latency, CPU per node', 12, '--json'),
    Benchmark('main_job', 'bench_main_job.py', ('--runs', '2', '--modes', 'processes,in-process'),
              '`rubber-rig bench` (make bench) timed from outside: latency, CPU per node process, the load', 10,
              '--json'),
    Benchmark('conformance_load', 'bench_conformance_load.py', ('--runs', '3'), '`rubber-rig conformance --sim` in '
              'a network namespace, run after run: the verdict of each timing requirement (under '
              'benchmarks/busy_load.py: is this host\'s lateness ever blamed on the controller?)', 6),
    Benchmark('idle_nodes', 'bench_idle_nodes.py', ('--rounds', '2'), 'the four node processes at rest: CPU, '
              'executor wake-ups and CPU per wake-up of each (what their timers cost)', 3, '--json'),
    Benchmark('identification', 'bench_identification.py', ('--seeds', '20'), 'does every fit tell the truth: '
              '19 cases x 20 noise seeds', 60, '--json'),
    Benchmark('soak', 'bench_soak.py', (), '30 minutes of churn: kills, restarts, clients, a second suite', 32,
              '--json'),
)


def _git(*args) -> str:
    try:
        return subprocess.run(['git', *args], cwd=ROOT, capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ''


def machine() -> str:
    """What the figures were measured on: cores, memory, Python."""
    mem = ''
    try:
        with open('/proc/meminfo', encoding='ascii') as fh:
            mem = f", {int(fh.readline().split()[1]) / 2 ** 20:.0f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    return f'{os.cpu_count()} cores{mem}, {platform.system()} {platform.machine()}, Python {platform.python_version()}'


def run(bench: Benchmark, out: Path = OUT, extra: tuple = ()) -> dict:
    """Run one benchmark as its own process and write <name>.md and <name>.json into `out`; returns the record."""
    out.mkdir(parents=True, exist_ok=True)
    results = out / f'{bench.name}.results.tmp.json'
    cmd = [sys.executable, str(ROOT / 'benchmarks' / bench.script), *bench.args, *extra]
    if bench.json_arg:
        cmd += [bench.json_arg, str(results)]
    shown = ' '.join(['.venv/bin/python', f'benchmarks/{bench.script}', *bench.args, *extra])
    # the pages this runner writes do not make the measured code 'uncommitted'
    dirty = bool(_git('status', '--porcelain', '--untracked-files=no', '--', '.', ':!docs/benchmarks'))
    record = {'name': bench.name, 'what': bench.what, 'command': shown, 'commit': _git('rev-parse', '--short', 'HEAD')
              + (' (with uncommitted changes)' if dirty else ''), 'machine': machine(),
              'started': time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}
    t0 = time.monotonic()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    record.update(seconds=round(time.monotonic() - t0, 1), returncode=proc.returncode, output=proc.stdout)
    if proc.returncode != 0:
        record['stderr'] = proc.stderr[-4000:]
    if results.exists():
        try:
            record['results'] = json.loads(results.read_text(encoding='utf-8'))
        except json.JSONDecodeError as exc:
            record['results_error'] = f'{bench.script} wrote JSON that does not parse: {exc}'
        results.unlink()
    (out / f'{bench.name}.json').write_text(json.dumps(record, indent=1, default=str) + '\n', encoding='utf-8')
    (out / f'{bench.name}.md').write_text(markdown(record), encoding='utf-8')
    return record


def markdown(record: dict) -> str:
    """The benchmark's page: how it ran, then its own output."""
    status = 'ok' if record['returncode'] == 0 else f"FAILED (exit status {record['returncode']})"
    head = [f"# Benchmark: {record['name']}", '', f"{record['what']}.", '',
            '| | |', '| --- | --- |',
            f"| command | `{record['command']}` |", f"| commit | {record['commit']} |",
            f"| run | {record['started']}, {record['seconds']:.0f} s wall, {status} |",
            f"| machine | {record['machine']} |", '',
            'Written by `benchmarks/run_all.py`; what follows is the benchmark\'s own output, unedited.', '']
    output = record['output'].rstrip()
    if not any(line.startswith(('|', '#')) for line in output.splitlines()):
        output = f'```text\n{output}\n```'      # plain columns: keep them aligned
    body = [output]
    if 'stderr' in record:
        body += ['', '## Error output (last 4000 characters)', '', '```', record['stderr'].rstrip(), '```']
    return '\n'.join(head + body) + '\n'


def write_index(out: Path = OUT) -> Path:
    """docs/benchmarks/README.md: every benchmark with the date, commit and status of its latest written run."""
    lines = ['# Benchmark results', '', 'Written by `benchmarks/run_all.py` (`make benchmarks`); each page says '
             'the command, commit and machine of its run.', '', '| benchmark | what it measures | run | commit | '
             'status |', '| --- | --- | --- | --- | --- |']
    for bench in BENCHMARKS:
        path = out / f'{bench.name}.json'
        if not path.exists():
            lines.append(f'| {bench.name} | {bench.what} | not run yet | | |')
            continue
        rec = json.loads(path.read_text(encoding='utf-8'))
        status = ('imported from an earlier README, not generated' if rec.get('imported')
                  else 'ok' if rec.get('returncode') == 0 else f"failed ({rec.get('returncode')})")
        lines.append(f"| [{bench.name}]({bench.name}.md) | {bench.what} | {rec.get('started', '?')}, "
                     f"{rec.get('seconds', 0):.0f} s | {rec.get('commit', '?')} | {status} |")
    index = out / 'README.md'
    index.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return index


def main(argv=None) -> int:
    names = [b.name for b in BENCHMARKS]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--only', help=f'comma-separated subset of: {", ".join(names)}')
    ap.add_argument('--list', action='store_true', help='list the benchmarks and their approximate duration')
    ap.add_argument('--out', type=Path, default=OUT, help='where the pages go (default docs/benchmarks)')
    args = ap.parse_args(argv)
    chosen = list(BENCHMARKS)
    if args.only:
        wanted = [n.strip() for n in args.only.split(',') if n.strip()]
        unknown = sorted(set(wanted) - set(names))
        if unknown:
            ap.error(f'unknown benchmark {unknown[0]!r}; there are: {", ".join(names)}')
        chosen = [b for b in BENCHMARKS if b.name in wanted]
    if args.list:
        for b in chosen:
            print(f'{b.name:15s} ~{b.minutes:g} min  {b.what}')
        print(f'total ~{sum(b.minutes for b in chosen):g} min')
        return 0
    failed = []
    for b in chosen:
        print(f'[{time.strftime("%H:%M:%S")}] {b.name} (~{b.minutes:g} min) ...', flush=True)
        rec = run(b, args.out)
        print(f"    {'ok' if rec['returncode'] == 0 else 'FAILED'} in {rec['seconds']:.0f} s -> "
              f"{args.out / (b.name + '.md')}", flush=True)
        if rec['returncode'] != 0:
            failed.append(b.name)
    write_index(args.out)
    if failed:
        print('failed: ' + ', '.join(failed), file=sys.stderr)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
