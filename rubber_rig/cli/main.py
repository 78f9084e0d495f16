"""`rubber-rig` command line: one entry point, one sub-command per job."""
import argparse
import importlib
import sys


class CommandError(RuntimeError):
    """A job could not be done for a reason the message states (no traceback is shown)."""

# sub-command -> module that provides `add_arguments(parser)` and `run(args) -> int`
COMMANDS = {
    'bench': 'rubber_rig.cli.bench',
    'props': 'rubber_rig.cli.props',
    'fit': 'rubber_rig.cli.fit',
    'report': 'rubber_rig.cli.report',
    'recover': 'rubber_rig.cli.recover',
    'info': 'rubber_rig.cli.info',
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='rubber-rig', description=__doc__)
    sub = parser.add_subparsers(dest='command', required=True)
    available = {}
    for name, module_name in COMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:  # sub-command not built yet
                continue
            raise
        p = sub.add_parser(name, help=(module.__doc__ or '').strip().splitlines()[0])
        module.add_arguments(p)
        available[name] = module
    args = parser.parse_args(argv)
    try:
        return int(available[args.command].run(args) or 0)
    except KeyboardInterrupt:
        return 130
    except (ValueError, FileNotFoundError) as exc:  # bad input: a clear message, no traceback
        print(f'rubber-rig {args.command}: error: {exc}', file=sys.stderr)
        return 2
    except CommandError as exc:                      # the job failed for a stated reason
        print(f'rubber-rig {args.command}: error: {exc}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
