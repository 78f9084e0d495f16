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

"""Run the simulated rig as a separate process on a process-crossing bus.

    python -m rubber_rig.rig.sim --config rig.json      (RigConfig as JSON; backend e.g. udp_multicast)
    python -m rubber_rig.rig.sim --config-json '{"backend": "udp_multicast", "paced": false}'
    ... --timing-log late.txt      (paced: every deadline missed by 2 ms or more, 'start end' wall-clock s)
Stops on SIGTERM/SIGINT.
"""
import argparse
import json
import signal
import sys

from ..can.bus import open_bus
from ..can.udp_socket import RECEIVE_BUFFER, dropped, socket_inode
from ..config import ConfigError, RigConfig
from .controller import SimController


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='python -m rubber_rig.rig.sim', description=__doc__.splitlines()[0])
    parser.add_argument('--config', help='RigConfig JSON file')
    parser.add_argument('--config-json', help='RigConfig as a JSON string')
    parser.add_argument('--timing-log', help="append this process's missed deadlines (paced) to this file, one "
                        "'start end' line each (wall-clock s): the host was late, not the controller it simulates "
                        '(rubber-rig conformance --sim reads it)')
    args = parser.parse_args(argv)
    try:
        data = json.loads(args.config_json) if args.config_json else (
            json.load(open(args.config)) if args.config else {})
        cfg = RigConfig.from_dict(data)
        if cfg.backend == 'sim':
            raise ConfigError('backend', "a separate-process rig needs a process-crossing "
                              "python-can interface (udp_multicast, socketcan vcan0, ...), not 'sim'")
    except (ValueError, OSError) as exc:
        print(f'rubber_rig.rig.sim: error: {exc}', file=sys.stderr)
        return 2
    # a deep receive queue: setpoints and heartbeats that arrive while this process waits for a CPU are read
    # late, never lost (it reads its whole queue before each tick)
    bus = open_bus(cfg, receive_buffer=RECEIVE_BUFFER)
    sim = SimController(bus, cfg.sample_rate, cfg.sim, cfg.paced, profile=cfg.frame_profile)
    if args.timing_log:
        sim.timing_log.file = open(args.timing_log, 'a', encoding='utf-8', buffering=1)   # noqa: SIM115 - whole run
        inode = socket_inode(bus)
        sim.timing_log.drops = lambda: dropped(inode)     # frames its socket lost are this host's loss too
    signal.signal(signal.SIGTERM, lambda *_: sim._stop.set())
    signal.signal(signal.SIGINT, lambda *_: sim._stop.set())
    print('rubber_rig.rig.sim: serving', cfg.backend, cfg.channel or '', flush=True)
    try:
        sim.run_forever()
    finally:
        bus.shutdown()
        sim.timing_log.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
