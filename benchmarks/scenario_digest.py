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

"""Digests of what each scenario of bench_scenario.py runs: its samples, the driver's events and counters, the
detectors' events, the setpoints streamed, the block results, and the bytes of its MCAP recording. Run it on two
commits (PYTHONPATH set to each checkout) and compare the lines: an optimisation of the harness must not change
one of them.

    PYTHONPATH=. .venv/bin/python benchmarks/scenario_digest.py > after.txt
"""
from __future__ import annotations

import hashlib
import os
import pathlib
import tempfile

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402
from bench_scenario import CASES  # noqa: E402


def digest(*parts) -> str:
    """The first 16 hex digits of the SHA-256 of `parts` (arrays by their bytes, anything else by its repr)."""
    h = hashlib.sha256()
    for p in parts:
        h.update(np.ascontiguousarray(p).tobytes() if isinstance(p, np.ndarray) else repr(p).encode())
    return h.hexdigest()[:16]


def case_digests(make, path: pathlib.Path) -> dict:
    """Digest by what was run of one scenario, recorded to `path`."""
    scenario = make()
    scenario.record = path
    o = scenario.run()
    return {'samples': digest(o.sequence, o.displacement, o.force, o.setpoint),
            'events': digest(o.events, o.faults, o.counters, o.reason, o.completed, o.ended_at, o.played_end),
            'detections': digest([(t, repr(e)) for t, e in o.detections]),
            'streamed': digest(*[np.asarray([first]) for first, _ in o.streamed], *[x for _, x in o.streamed]),
            'blocks': digest([repr(b) for b in o.blocks]),
            'recording': hashlib.sha256(path.read_bytes()).hexdigest()[:16]}


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for name, make, _ in CASES:
            d = case_digests(make, pathlib.Path(tmp) / 'scenario.mcap')    # (the name is in the file)
            print(f'{name}: ' + ' '.join(f'{k}={v}' for k, v in d.items()))


if __name__ == '__main__':
    main()
