"""Entry point of the ``hiros`` command: dispatches to ``hiros_cli.commands.<name>``.

Subcommand modules are imported only when listed in ``--help`` or run, so ``hiros convert``
does not pay for importing the calibration or the pipeline.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from types import ModuleType

from hiros_core.errors import HirosError

COMMANDS = (
    "demo",
    "calibrate",
    "run",
    "simulate",
    "evaluate",
    "play",
    "topic",
    "param",
    "convert",
    "export",
    "bench",
)


def _load(name: str) -> ModuleType | None:
    try:
        return importlib.import_module(f"hiros_cli.commands.{name}")
    except ModuleNotFoundError as exc:
        if exc.name == f"hiros_cli.commands.{name}":
            return None
        raise


def build_parser() -> argparse.ArgumentParser:
    """The full parser with every available subcommand."""
    parser = argparse.ArgumentParser(
        prog="hiros",
        description=(
            "Markerless multi-camera motion capture: calibrate cameras from people's motion, "
            "track, merge, optimise and filter skeletons. Offline commands need no ROS 2 network."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        module = _load(name)
        if module is None:
            continue
        child = sub.add_parser(
            name,
            help=module.HELP,
            description=(module.__doc__ or module.HELP).strip(),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(child)
        child.set_defaults(_module=module)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``hiros`` with ``argv``; returns the exit code (non-zero with one clear sentence)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_module", None):
        parser.print_help()
        return 2
    previous = _terminate_as_interrupt()
    try:
        return int(args._module.run(args) or 0)
    except Terminated:
        print(f"hiros {args.command}: terminated (SIGTERM)", file=sys.stderr)
        return 128 + signal.SIGTERM
    except HirosError as exc:
        print(f"hiros {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # an output path that cannot be written: a folder there, no room
        print(f"hiros {args.command}: error: {_os_problem(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"hiros {args.command}: interrupted", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


class Terminated(BaseException):
    """SIGTERM met in the command, raised where the command is.

    Its ``finally`` blocks then run: an output being written is removed (``hiros_core.outputs``).
    """


def _terminate_as_interrupt() -> object:
    """Turn SIGTERM into ``Terminated`` in this process (a forked child just exits).

    Python's default for SIGTERM ends the process at once, without cleanup: a run stopped so
    left a cut output under its final name. Returns the handler it replaced (None outside
    the main thread, where no handler can be set).
    """
    main_pid = os.getpid()

    def handler(signum: int, frame: object) -> None:
        if os.getpid() != main_pid:  # a forked worker (hiros run's reader) stops at once
            os._exit(128 + signum)
        raise Terminated

    try:
        return signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (a test calling main from a thread)
        return None


def _os_problem(exc: OSError) -> str:
    """``PATH: reason`` for the user, without Python's ``[Errno N]`` decoration."""
    if exc.filename is None or not exc.strerror:
        return str(exc)
    return f"{exc.filename}: {exc.strerror}"


if __name__ == "__main__":
    sys.exit(main())
