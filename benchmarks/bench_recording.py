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

"""Recording benchmark: write throughput, CPU use of the recorder at 1 kHz, file size per minute.

    RMW_IMPLEMENTATION=rmw_fastrtps_cpp .venv/bin/python benchmarks/bench_recording.py [--duration 10]

1. Core throughput: one minute of batched rig samples (1 kHz: 20 samples/batch = 50 msg/s; 10 kHz:
   100 samples/batch = 100 msg/s), as the CDR bytes the recorder node receives, written as fast as
   possible through Recorder (chunking, zstd, gap tracking): msg/s, MB/s, real-time factor, and
   the file size of that minute. Also the path that encodes dicts in Python (ROS-free producers).
2. Core CPU, paced: the same stream at its real rate for --duration seconds; time.process_time.
   load_recording time for that minute (the fitting side).
3. Recorder node CPU (target < 10 % of one core at 1 kHz): the node as its own process, fed by a
   real rclpy publisher in this process at the real rate; CPU from /proc/<pid>/stat (utime+stime),
   and a check that every batch was recorded.
"""
import os

if not os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):   # DDS discovery stays on this machine unless asked
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'   # (README "Networking"); before rclpy loads
import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from rubber_rig.recording import Recorder, load_recording  # noqa: E402

CASES = {'1 kHz': (1000, 20), '10 kHz': (10000, 100)}      # sample rate, samples per batch


def make_batch(k, rate, n):
    from msg_defs.msg import RigSampleBatch
    first = k * n
    i = np.arange(first, first + n)
    t = i / rate
    rng = np.random.default_rng(k)
    m = RigSampleBatch()
    m.first_sequence = first
    m.sample_period = 1.0 / rate
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(int(first * 1e9 / rate), 10**9)
    x = 2e-3 * np.sin(2 * np.pi * 5 * t)
    # a 16-bit ADC's resolution, as the rig delivers it (noise makes zstd's job realistic)
    m.displacement = np.round((x + rng.normal(0, 2e-6, n)) / 1e-7) * 1e-7
    m.force = np.round((4e3 * np.sin(2 * np.pi * 5 * t + 0.2) + rng.normal(0, 5, n)) / 0.2) * 0.2
    m.setpoint = x
    m.temperature = 23.0
    return m


def serialized_minute(rate, n):
    from rclpy.serialization import serialize_message
    count = int(60 * rate / n)
    return [serialize_message(make_batch(k, rate, n)) for k in range(count)]


def core_throughput(tmp, name, rate, n, msgs, as_dict=False):
    rec = Recorder(tmp)
    rec.start(tmp / name)
    period_ns = int(n * 1e9 / rate)
    items = msgs
    if as_dict:
        items = [make_batch(k, rate, n) for k in range(len(msgs))]
    t0, c0 = time.perf_counter(), time.process_time()
    for k, data in enumerate(items):
        rec.write('/rig/samples', 'msg_defs/msg/RigSampleBatch', data, 10**18 + k * period_ns)
    files = rec.stop()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    size = sum(f.stat().st_size for f in files)
    payload = sum(len(m) for m in msgs)
    t0 = time.perf_counter()
    r = load_recording(files[0])
    read = time.perf_counter() - t0
    assert len(r) == len(msgs) * n and r.samples_lost == 0
    return dict(msgs=len(msgs), wall=wall, cpu=cpu, size=size, payload=payload, read=read)


def core_paced(tmp, rate, n, msgs, duration):
    rec = Recorder(tmp)
    rec.start(tmp / f'paced_{rate}')
    period = n / rate
    count = int(duration / period)
    t0, c0 = time.perf_counter(), time.process_time()
    for k in range(count):
        delay = t0 + k * period - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        rec.write('/rig/samples', 'msg_defs/msg/RigSampleBatch', msgs[k % len(msgs)], time.time_ns())
    rec.stop()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return cpu / wall


def proc_cpu_seconds(pid):
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def node_cpu(tmp, rate, n, duration):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from msg_defs.msg import RigSampleBatch
    from rubber_rig.nodes import topics

    ns = f'/bench{rate}'
    out = tmp / f'node_{rate}'
    env = dict(os.environ, RMW_IMPLEMENTATION=os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp'))
    proc = subprocess.Popen([sys.executable, '-m', 'rubber_rig.nodes.recorder_node', '--ros-args',
                             '-r', f'__ns:={ns}', '-p', f'output_dir:={out}'],
                            env=env, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Node('bench_rig', namespace=ns, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    stats = {}

    def on_diag(msg):
        for s in msg.status:
            if s.hardware_id == str(out):
                stats.update({kv.key: kv.value for kv in s.values})
    try:
        node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diag, 10)
        pub = node.create_publisher(RigSampleBatch, topics.SAMPLES, topics.STREAM_QOS)
        batches = [make_batch(k, rate, n) for k in range(200)]
        deadline = time.monotonic() + 30
        while (stats.get('topics') != '1' or pub.get_subscription_count() < 1) and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
        count = int(duration * rate / n)
        state = {'k': 0}

        def tick():
            k = state['k']
            if k < count:
                m = batches[k % len(batches)]
                m.first_sequence = k * n
                pub.publish(m)
                state['k'] = k + 1
        node.create_timer(n / rate, tick)
        c0, t0 = proc_cpu_seconds(proc.pid), time.monotonic()
        while state['k'] < count:
            ex.spin_once(timeout_sec=0.01)
        c1, t1 = proc_cpu_seconds(proc.pid), time.monotonic()
        deadline = time.monotonic() + 30
        while stats.get('messages_written') != str(count) and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
        written = int(stats.get('messages_written', -1))
        lost = int(stats.get('samples_lost', -1))
    finally:
        proc.send_signal(2)
        proc.wait(timeout=30)
        ex.remove_node(node)
        node.destroy_node()
        ex.shutdown()
        rclpy.try_shutdown(context=ctx)
    return dict(cpu=(c1 - c0) / (t1 - t0), sent=count, written=written, lost=lost)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=10.0, help='paced runs [s]')
    parser.add_argument('--no-node', action='store_true', help='skip the recorder node process runs')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        print('== core write throughput (one minute of data, CDR bytes as the node receives them) ==')
        minutes = {}
        for label, (rate, n) in CASES.items():
            msgs = serialized_minute(rate, n)
            minutes[label] = msgs
            r = core_throughput(tmp, f'tp_{rate}', rate, n, msgs)
            print(f'{label:>6}: {r["msgs"] / r["wall"]:9.0f} msg/s  {r["payload"] / r["wall"] / 1e6:6.1f} MB/s '
                  f'payload  {r["msgs"] * n / r["wall"] / 1e6:5.2f} Msamples/s  '
                  f'real-time x{60 / r["wall"]:.0f}  ({n} samples/batch, {len(msgs[0])} B/msg)')
            print(f'        per CPU second (robust to other load on the machine): '
                  f'{r["msgs"] / r["cpu"]:.0f} msg/s, {r["payload"] / r["cpu"] / 1e6:.1f} MB/s')
            print(f'        file size per minute: {r["size"] / 1e6:.2f} MB '
                  f'(payload {r["payload"] / 1e6:.2f} MB, zstd ratio {r["payload"] / r["size"]:.2f}); '
                  f'load_recording of that minute: {r["read"]:.2f} s')
        rate, n = CASES['1 kHz']
        r = core_throughput(tmp, 'tp_dict', rate, n, minutes['1 kHz'], as_dict=True)
        print(f'1 kHz, messages encoded by the core (rosidl objects -> CDR in Python): '
              f'{r["msgs"] / r["wall"]:.0f} msg/s')
        print(f'== core CPU, paced at the real rate for {args.duration:.0f} s (time.process_time) ==')
        for label, (rate, n) in CASES.items():
            print(f'{label:>6}: {100 * core_paced(tmp, rate, n, minutes[label], args.duration):5.2f} % of one core')
        if not args.no_node:
            print(f'== recorder node process, real rclpy publisher at the real rate, {args.duration:.0f} s ==')
            for label, (rate, n) in CASES.items():
                r = node_cpu(tmp, rate, n, args.duration)
                ok = 'all recorded' if r['written'] == r['sent'] and r['lost'] == 0 else 'LOSS'
                print(f'{label:>6}: {100 * r["cpu"]:5.2f} % of one core  ({r["sent"]} batches sent, '
                      f'{r["written"]} written, {r["lost"]} samples lost: {ok})')
            print('target: recorder < 10 % of one core at 1 kHz')


if __name__ == '__main__':
    main()
