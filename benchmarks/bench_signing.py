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

"""The cost of authenticated commands and samples (issue 35): µs to sign and to verify one batch, and the CPU share
that takes at the suite's message rates, at 1 kHz and 10 kHz.

    .venv/bin/python benchmarks/bench_signing.py [--repeats 2000] [--json out.json]

What is timed is what a node does per message (rubber_rig.nodes.auth.NodeAuth on real rosidl messages): flatten
the message's fields, encode them canonically (rubber_rig.security.canonical) and HMAC-SHA256 them, then, on the
receiving side, the same plus the comparison and the replay check. Batch sizes are the shipped configuration's:
a sample batch per 10 ms (10 samples at 1 kHz, 100 at 10 kHz) and a setpoint batch per stream_period 40 ms
(20 and 200 setpoints). The CPU share is per node and per core: signatures made and checked per second times
their cost. A forged batch costs its receiver one verification (the tag is compared before anything else), so
the refusal rate one core sustains is 1 / verify time. The recorder, which subscribes raw, also turns the CDR bytes
of each sample and setpoint batch into a message before it checks it (timed too).
"""
from __future__ import annotations

import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
import argparse  # noqa: E402
import copy  # noqa: E402
import functools  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np
from rclpy.serialization import deserialize_message, serialize_message

from msg_defs.msg import Heartbeat
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes.auth import HEARTBEAT, SAMPLES, SETPOINT_STREAM, NodeAuth

KEY = bytes(range(32))
SAMPLE_BATCH_PERIOD = 0.01     # [s] rig_sim.yaml: samples published every 10 ms
SETPOINT_BATCH_PERIOD = 0.04   # [s] the excitation's stream_period (config/rig_sim.yaml)
HEARTBEATS_PER_S = 4.0         # every node, every 0.25 s


def messages(rate: float):
    """(name, message, purpose, messages per second) of one rate."""
    n_samples, n_setpoints = round(rate * SAMPLE_BATCH_PERIOD), round(rate * SETPOINT_BATCH_PERIOD)
    x = np.sin(np.arange(max(n_samples, n_setpoints)) * 0.01) * 1e-3
    samples = conv.sample_batch_msg(10**6, 1.8e9, 1 / rate, x[:n_samples], x[:n_samples] * 1e6, x[:n_samples],
                                    23.0, 0, 0)
    setpoints = conv.setpoint_batch_msg(10**6, 1 / rate, x[:n_setpoints], 3, t=1.8e9, stream_id=366189001,
                                        source='/rig/excitation')
    beat = Heartbeat(node='/rig/excitation', pid=4242, count=17, state='running')
    return [(f'samples ({n_samples})', samples, SAMPLES, 1 / SAMPLE_BATCH_PERIOD),
            (f'setpoints ({n_setpoints})', setpoints, SETPOINT_STREAM, 1 / SETPOINT_BATCH_PERIOD),
            ('heartbeat', beat, HEARTBEAT, HEARTBEATS_PER_S)]


def time_per_call(fn, repeats: int) -> tuple[float, float]:
    """(median, 99th percentile) [µs] of `repeats` calls of fn()."""
    times = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        times[i] = time.perf_counter_ns() - t0
    return float(np.median(times)) * 1e-3, float(np.percentile(times, 99)) * 1e-3


def measure(rate: float, repeats: int) -> list[dict]:
    rows = []
    signer = NodeAuth('/rig/excitation', KEY, True, '(benchmark)')
    verifier = NodeAuth('/rig/rig_driver', KEY, True, '(benchmark)')
    for name, msg, purpose, per_s in messages(rate):
        sign = time_per_call(functools.partial(signer.sign, msg, purpose), repeats)
        # distinct counters: each one verifies (no replay refusals)
        signed = iter([signer.sign(copy.deepcopy(msg), purpose) for _ in range(repeats)])
        verify = time_per_call(lambda it=signed, p=purpose: verifier.verify(next(it), p, '/bench'), repeats)
        assert verifier.verifier.refused_total == 0, verifier.lines()
        rows.append({'rate_hz': rate, 'message': name, 'per_s': per_s, 'sign_us': sign[0], 'sign_p99_us': sign[1],
                     'verify_us': verify[0], 'verify_p99_us': verify[1],
                     'cpu_sign_pct': per_s * sign[0] * 1e-4, 'cpu_verify_pct': per_s * verify[0] * 1e-4})
    return rows


def forged_refusal(repeats: int) -> dict:
    """µs to refuse a forged sample batch (wrong tag) at 10 kHz size: what a flood costs its receiver."""
    verifier = NodeAuth('/rig/excitation', KEY, True, '(benchmark)')
    msg = messages(10000.0)[0][1]
    msg.signature.link, msg.signature.counter, msg.signature.tag = '/x', int(time.time() * 1e6), list(range(32))
    med, p99 = time_per_call(lambda: verifier.verify(msg, SAMPLES, '/bench'), repeats)
    return {'refuse_us': med, 'refuse_p99_us': p99, 'refusals_per_s_one_core': 1e6 / med}


def _check_cdr(recorder: NodeAuth, data, cls) -> str:
    return recorder.verify(deserialize_message(next(data), cls), SAMPLES, '/bench')


def recorder_check(repeats: int) -> dict:
    """µs the recorder spends on one sample batch before writing it: CDR bytes -> message -> verify."""
    out = {}
    for rate in (1000.0, 10000.0):
        signer, recorder = NodeAuth('/rig/rig_driver', KEY, True, '-'), NodeAuth('/rig/recorder', KEY, True, '-')
        msg = messages(rate)[0][1]
        data = iter([serialize_message(signer.sign(copy.deepcopy(msg), SAMPLES)) for _ in range(repeats)])
        check = functools.partial(_check_cdr, recorder, data, type(msg))
        us, p99 = time_per_call(check, repeats)
        out[f'{rate / 1000:g} kHz'] = {'us': us, 'p99_us': p99, 'cpu_pct': us * 1e-4 / SAMPLE_BATCH_PERIOD}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--repeats', type=int, default=2000)
    ap.add_argument('--json', help='write the figures here as JSON')
    args = ap.parse_args(argv)
    rows = measure(1000.0, args.repeats) + measure(10000.0, args.repeats)
    print('| rate | message (values) | per s | sign µs (p99) | verify µs (p99) | CPU sign % | CPU verify % |')
    print('| --- | --- | --- | --- | --- | --- | --- |')
    for r in rows:
        print(f"| {r['rate_hz'] / 1000:g} kHz | {r['message']} | {r['per_s']:g} | {r['sign_us']:.1f} "
              f"({r['sign_p99_us']:.1f}) | {r['verify_us']:.1f} ({r['verify_p99_us']:.1f}) | "
              f"{r['cpu_sign_pct']:.3f} | {r['cpu_verify_pct']:.3f} |")
    for rate in (1000.0, 10000.0):
        mine = [r for r in rows if r['rate_hz'] == rate]
        driver = mine[0]['cpu_sign_pct'] + mine[1]['cpu_verify_pct'] + 4 * mine[2]['cpu_verify_pct'] \
            + mine[2]['cpu_sign_pct']
        subscriber = mine[0]['cpu_verify_pct'] + mine[2]['cpu_sign_pct']
        print(f'\n{rate / 1000:g} kHz: rig_driver (signs samples, verifies setpoints and beats) {driver:.3f} % of a '
              f'core; each sample subscriber (verifies samples, signs its beats) {subscriber:.3f} %')
    recorder = recorder_check(args.repeats)
    for rate, r in recorder.items():
        print(f"recorder at {rate}: CDR -> message -> verify {r['us']:.1f} µs per sample batch "
              f"(p99 {r['p99_us']:.1f}), {r['cpu_pct']:.3f} % of a core")
    forged = forged_refusal(args.repeats)
    print(f"\nrefusing a forged 10 kHz sample batch: {forged['refuse_us']:.1f} µs (p99 {forged['refuse_p99_us']:.1f}): "
          f"one core refuses {forged['refusals_per_s_one_core']:.0f} forged batches/s")
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'rows': rows, 'recorder': recorder, 'forged': forged}, f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
