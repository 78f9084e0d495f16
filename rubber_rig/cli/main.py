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

"""`rubber-rig` command line: one entry point, one sub-command per job."""
import argparse
import importlib
import os
import sys

from rubber_rig import __version__

# DDS discovery stays on this machine unless the user opens it (README "Networking"): set before any
# sub-command imports rclpy, and inherited by the node processes the bench starts.
DISCOVERY_RANGE_VARIABLE = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
DISCOVERY_RANGE_DEFAULT = 'LOCALHOST'


class CommandError(RuntimeError):
    """A job could not be done for a reason the message states (no traceback is shown)."""


# sub-command -> module that provides `add_arguments(parser)` and `run(args) -> int`, optionally
# `check_arguments(args) -> message or None` for option combinations argparse cannot express
COMMANDS = {
    'bench': 'rubber_rig.cli.bench',
    'props': 'rubber_rig.cli.props',
    'fit': 'rubber_rig.cli.fit',
    'models': 'rubber_rig.cli.models',
    'report': 'rubber_rig.cli.report',
    'recover': 'rubber_rig.cli.recover',
    'info': 'rubber_rig.cli.info',
    'canlog': 'rubber_rig.cli.canlog',
    'simulate': 'rubber_rig.cli.simulate',
    'conformance': 'rubber_rig.cli.conformance',
    'keys': 'rubber_rig.cli.keys',
    'hold': 'rubber_rig.cli.hold',
}


def keep_discovery_local(environ=os.environ) -> str:
    """Default ROS_AUTOMATIC_DISCOVERY_RANGE to LOCALHOST when unset (an empty value counts as unset:
    rcl reads it as the network-wide default). Returns the range in effect.
    """
    if not environ.get(DISCOVERY_RANGE_VARIABLE):
        environ[DISCOVERY_RANGE_VARIABLE] = DISCOVERY_RANGE_DEFAULT
    return environ[DISCOVERY_RANGE_VARIABLE]


def _os_error_text(exc: OSError) -> str:
    paths = [p for p in (exc.filename, exc.filename2) if p is not None]
    reason = exc.strerror or type(exc).__name__
    return f'{" -> ".join(str(p) for p in paths)}: {reason}' if paths else str(exc) or reason


# sub-commands whose numerics run faster on one BLAS thread (rubber_rig.fitting.blas): the thread count is an
# environment variable OpenBLAS reads when numpy loads, so it is set before the sub-command modules import numpy
ONE_BLAS_THREAD = ('fit',)


def main(argv=None) -> int:
    keep_discovery_local()
    words = [a for a in (sys.argv[1:] if argv is None else argv) if not a.startswith('-')]
    if words and words[0] in ONE_BLAS_THREAD:
        os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
    parser = argparse.ArgumentParser(prog='rubber-rig', description=__doc__)
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', required=True)
    available, parsers = {}, {}
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(module_name)
        p = sub.add_parser(name, help=(module.__doc__ or '').strip().splitlines()[0])
        module.add_arguments(p)
        available[name], parsers[name] = module, p
    args = parser.parse_args(argv)
    module = available[args.command]
    check = getattr(module, 'check_arguments', None)
    problem = check(args) if check else None
    if problem:
        parsers[args.command].error(problem)         # usage + message, exit 2
    try:
        return int(module.run(args) or 0)
    except KeyboardInterrupt:
        return 130
    except CommandError as exc:                      # the job failed for a stated reason
        print(f'rubber-rig {args.command}: error: {exc}', file=sys.stderr)
        return 1
    except FileNotFoundError as exc:                 # a named input does not exist: bad input
        print(f'rubber-rig {args.command}: error: {_os_error_text(exc)}', file=sys.stderr)
        return 2
    except ValueError as exc:                        # bad input: a clear message, no traceback
        print(f'rubber-rig {args.command}: error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:                           # an output could not be written (read-only, full, ...)
        print(f'rubber-rig {args.command}: error: {_os_error_text(exc)}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
