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

"""How many threads OpenBLAS uses for the fit's linear algebra.

A fit's matrices are small (thousands of residuals by at most a dozen parameters); a multithreaded OpenBLAS
spins its threads on them and, on the lab's 2-core machine under load, costs 2-3 x the CPU time of one thread
for the same result (an 8-parameter fit on 20-50 Hz: 4.7 s against 1.8 s, docs/benchmarks/identification_notes.md).
OpenBLAS reads ``OPENBLAS_NUM_THREADS`` once, when it is loaded: the ``rubber-rig fit`` entry sets it before
numpy loads (``ENVIRONMENT``), and :func:`set_blas_threads` sets the libraries already loaded (a fit called from
a Python session that imported numpy first) through OpenBLAS's own ``*_set_num_threads``.
"""
from __future__ import annotations

import ctypes
import os

ENVIRONMENT = 'OPENBLAS_NUM_THREADS'
DEFAULT_THREADS = 1
# numpy's and scipy's wheels bundle their own OpenBLAS under these names (64-bit integer build first)
_SETTERS = ('scipy_openblas_set_num_threads64_', 'scipy_openblas_set_num_threads', 'openblas_set_num_threads')


def threads_wanted(environ=os.environ) -> int:
    """The thread count the user asked for in ``OPENBLAS_NUM_THREADS`` (a positive integer), else 1."""
    try:
        n = int(environ.get(ENVIRONMENT, DEFAULT_THREADS))
    except ValueError:
        return DEFAULT_THREADS
    return n if n > 0 else DEFAULT_THREADS


def loaded_openblas() -> list:
    """Paths of the OpenBLAS libraries mapped into this process (Linux: /proc/self/maps), else []."""
    try:
        with open('/proc/self/maps') as maps:
            paths = {line.split()[-1] for line in maps if 'openblas' in line.lower() and '/' in line}
    except OSError:
        return []
    return sorted(p for p in paths if os.path.isfile(p))


def set_blas_threads(n: int | None = None) -> dict:
    """Set every loaded OpenBLAS to ``n`` threads (default: :func:`threads_wanted`).

    Returns {library path: n} for the libraries set; a library without a known setter is left alone.
    """
    n = threads_wanted() if n is None else int(n)
    done = {}
    for path in loaded_openblas():
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in _SETTERS:
            setter = getattr(lib, name, None)
            if setter is not None:
                setter.argtypes = [ctypes.c_int]
                setter.restype = None
                setter(n)
                done[path] = n
                break
    return done
