#!/usr/bin/env python3
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

"""Benchmark of rubber_rig.models: streaming cost, batch throughput, fractional-operator accuracy.

Run: .venv/bin/python benchmarks/bench_models.py [--quick]

1. Streaming: cost per sample of ``step(x)`` of the full seed-000 model (fractional Zener + Berg,
   20 degC) at 1 kHz, default scheme and the paper's GL scheme. Target <= 20 us.
2. Batch: ``run(x)`` throughput on 2 M samples (a two-tone rig-like signal, and white noise that
   reverses direction every other sample - Berg's worst case). Target >= 5 M samples/s.
3. Accuracy of the viscoelastic branch vs seed 000 Eq. 11-13 over 0.05-50 Hz, time domain:
   the paper's GL scheme (N_t = 200, h = 1 ms), the default scheme at 1 kHz and 5 kHz, and the
   ``differint`` package's GL derivative (full-history FFT convolution) used as the operator in
   the Zener law, all from sine runs analysed over their last two cycles.
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
import argparse
import time

import numpy as np

from rubber_rig.analysis import harmonic_properties
from rubber_rig.models import build_model, load_parameter_set, sine_displacement, zener_complex_stiffness

P = load_parameter_set('seed000_20C')


def best_of(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times))


def streaming(n, repeats):
    rows = []
    x = 1e-3 * np.sin(2 * np.pi * 2.0 * np.arange(n) * 1e-3) + 1e-5 * np.random.default_rng(0).normal(size=n)
    xs = x.tolist()
    for scheme in ('default', 'paper'):
        m = build_model(P, 1e-3, scheme=scheme)

        def loop(m=m):
            m.reset()
            step = m.step
            for v in xs:
                step(v)
        best, med = best_of(loop, repeats)
        rows.append((scheme, best / n * 1e6, med / n * 1e6))
    return rows


def batch(n, repeats):
    t = np.arange(n) * 1e-3
    signals = {
        'two-tone 2 Hz + 13.7 Hz': 1e-3 * np.sin(2 * np.pi * 2 * t) + 2e-4 * np.sin(2 * np.pi * 13.7 * t),
        'white noise (worst case)': 1e-4 * np.random.default_rng(1).normal(size=n),
    }
    rows = []
    for scheme in ('default', 'paper'):
        m = build_model(P, 1e-3, scheme=scheme)
        for name, x in signals.items():
            if scheme == 'paper' and name.startswith('white'):
                continue
            m.run(x[:1000])   # warm-up

            def go(m=m, x=x):
                m.reset()
                m.run(x)
            best, med = best_of(go, repeats)
            rows.append((scheme, name, n / best / 1e6, n / med / 1e6))
    return rows


def zener_from_operator(d_hat):
    """Zener complex stiffness when the operator (j w)^alpha is replaced by ``d_hat`` (cf. Eq. 14)."""
    c = P.tau ** P.alpha * d_hat
    return (P.k0 + P.k_inf * c) / (1 + c)


def measure_model(scheme, fs, f, cycles):
    m = build_model(P, 1 / fs, scheme=scheme).elements[0]   # the viscoelastic element alone
    x = sine_displacement(f, 1e-3, 1 / fs, cycles)
    force = m.run(x).sum(axis=0)
    n = int(round(2 / (f / fs))) + 1
    h = harmonic_properties(x[-n:], force[-n:], 1 / fs, f)
    return h.k_dyn * np.exp(1j * h.loss_angle)


def measure_differint(fs, f, cycles):
    import differint.differint as dif
    x = sine_displacement(f, 1e-3, 1 / fs, cycles)
    d = dif.GL(P.alpha, x, 0.0, (x.size - 1) / fs, x.size)
    n = int(round(2 / (f / fs))) + 1
    hx = harmonic_properties(x[-n:], d[-n:], 1 / fs, f)   # "stiffness" of the operator = D1 / X1
    return zener_from_operator(hx.k_dyn * np.exp(1j * hx.loss_angle))


def accuracy(freqs, cycles):
    rows = []
    for f in freqs:
        k = zener_complex_stiffness(2 * np.pi * f, P.k0, P.k_inf, P.tau, P.alpha)
        res = [measure_model('paper', 1000, f, cycles), measure_model('default', 1000, f, cycles),
               measure_model('default', 5000, f, cycles), measure_differint(1000, f, cycles)]
        rows.append((f, k, [(r.real / k.real - 1, r.imag / k.imag - 1) for r in res]))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true', help='smaller runs (for a smoke check)')
    args = ap.parse_args(argv)
    n_stream, n_batch, reps = (20_000, 200_000, 2) if args.quick else (200_000, 2_000_000, 5)
    m = build_model(P, 1e-3)
    print(f'seed000_20C, default scheme at 1 kHz: {m.elements[0].bank.g.size} exponential modes, '
          f'fit error storage {m.elements[0].fit_error[0]:.1e}, loss {m.elements[0].fit_error[1]:.1e}')

    print(f'\n1. Streaming step(x), full seed-000 model, {n_stream} samples at 1 kHz (target <= 20 us/sample)')
    for scheme, best, med in streaming(n_stream, reps):
        print(f'   {scheme:8s} best {best:6.2f} us/sample   median {med:6.2f} us/sample   '
              f'({1e6 / best:,.0f} samples/s)')

    print(f'\n2. Batch run(x), full seed-000 model, {n_batch:,} samples (target >= 5 M samples/s)')
    for scheme, name, best, med in batch(n_batch, reps):
        print(f'   {scheme:8s} {name:26s} best {best:6.2f} M samples/s   median {med:6.2f} M samples/s')

    freqs = [0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50]
    cycles = 6
    print('\n3. Viscoelastic branch vs Eq. 11-13 (20 degC), time-domain steady state, relative error in % '
          '(storage dS, loss dL)')
    print(f'   {"f [Hz]":>7} {"K_S kN/mm":>9} {"K_L kN/mm":>9} | {"paper GL N_t=200 h=1ms":^21} | '
          f'{"default @1 kHz":^17} | {"default @5 kHz":^17} | {"differint GL @1 kHz":^19}')
    print(f'   {"":>7} {"":>9} {"":>9} | {"dS":>9} {"dL":>9}   | {"dS":>7} {"dL":>7}   | '
          f'{"dS":>7} {"dL":>7}   | {"dS":>8} {"dL":>8}')
    worst = np.zeros((4, 2))
    for f, k, errs in accuracy(freqs, cycles):
        e = np.array(errs) * 100
        worst = np.maximum(worst, np.abs(e))
        print(f'   {f:7.2f} {k.real / 1e6:9.3f} {k.imag / 1e6:9.4f} | {e[0, 0]:9.3f} {e[0, 1]:9.2f}   | '
              f'{e[1, 0]:7.3f} {e[1, 1]:7.2f}   | {e[2, 0]:7.3f} {e[2, 1]:7.2f}   | {e[3, 0]:8.3f} {e[3, 1]:8.2f}')
    print(f'   {"max |e|":>27} | {worst[0, 0]:9.3f} {worst[0, 1]:9.2f}   | {worst[1, 0]:7.3f} {worst[1, 1]:7.2f}   | '
          f'{worst[2, 0]:7.3f} {worst[2, 1]:7.2f}   | {worst[3, 0]:8.3f} {worst[3, 1]:8.2f}')
    print('   (target for the default scheme: |dS| <= 0.5 %, |dL| <= 2 %)')


if __name__ == '__main__':
    main()
