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

"""The fit's BLAS threads: one unless the user says otherwise, set on the OpenBLAS libraries really loaded."""
import ctypes
import os
import subprocess
import sys

import numpy as np
import scipy.linalg  # noqa: F401 - loads scipy's own OpenBLAS too

from rubber_rig.fitting.blas import loaded_openblas, set_blas_threads, threads_wanted

GETTERS = ('scipy_openblas_get_num_threads64_', 'scipy_openblas_get_num_threads', 'openblas_get_num_threads')


def _threads(path):
    lib = ctypes.CDLL(path)
    for name in GETTERS:
        getter = getattr(lib, name, None)
        if getter is not None:
            getter.restype = ctypes.c_int
            return getter()
    return None


def test_threads_wanted_reads_the_environment():
    assert threads_wanted({}) == 1
    assert threads_wanted({'OPENBLAS_NUM_THREADS': '3'}) == 3
    assert threads_wanted({'OPENBLAS_NUM_THREADS': 'many'}) == 1
    assert threads_wanted({'OPENBLAS_NUM_THREADS': '0'}) == 1


def test_set_blas_threads_sets_numpy_and_scipy_openblas():
    libs = loaded_openblas()
    assert any('numpy' in p for p in libs) and any('scipy' in p for p in libs)
    try:
        done = set_blas_threads(2)
        assert set(done) == set(libs)
        assert all(_threads(p) == 2 for p in libs)
        set_blas_threads(1)
        assert all(_threads(p) == 1 for p in libs)
        assert np.allclose(np.linalg.inv(np.eye(3) * 2.0), np.eye(3) / 2.0)   # still computes
    finally:
        set_blas_threads(threads_wanted())      # as the session had it


def test_the_fit_command_sets_one_thread_before_numpy_loads():
    """`rubber-rig fit` puts OPENBLAS_NUM_THREADS=1 in the environment before numpy is imported; a value the
    user set is kept.
    """
    code = ('import sys, os; from rubber_rig.cli import main as m\n'
            'try:\n    m.main(sys.argv[1:])\nexcept SystemExit:\n    pass\n'
            'print("numpy" in sys.modules, os.environ.get("OPENBLAS_NUM_THREADS"))')
    env = {k: v for k, v in os.environ.items() if k != 'OPENBLAS_NUM_THREADS'}
    out = subprocess.run([sys.executable, '-c', code, 'fit', '--help'], env=env, capture_output=True, text=True,
                         check=True).stdout.split()[-2:]
    assert out == ['True', '1']
    env['OPENBLAS_NUM_THREADS'] = '2'
    out = subprocess.run([sys.executable, '-c', code, 'fit', '--help'], env=env, capture_output=True, text=True,
                         check=True).stdout.split()[-2:]
    assert out == ['True', '2']
    env.pop('OPENBLAS_NUM_THREADS')
    out = subprocess.run([sys.executable, '-c', code, 'info', '--help'], env=env, capture_output=True, text=True,
                         check=True).stdout.split()[-2:]
    assert out == ['True', 'None']
