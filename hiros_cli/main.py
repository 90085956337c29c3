"""Entry point of the ``hiros`` command: dispatches to ``hiros_cli.commands.<name>``.

Subcommand modules are imported only when listed in ``--help`` or run, so ``hiros convert``
does not pay for importing the calibration or the pipeline.
"""

from __future__ import annotations

import argparse
import importlib
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
    try:
        return int(args._module.run(args) or 0)
    except HirosError as exc:
        print(f"hiros {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # an output path that cannot be written: a folder there, no room
        print(f"hiros {args.command}: error: {_os_problem(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"hiros {args.command}: interrupted", file=sys.stderr)
        return 130


def _os_problem(exc: OSError) -> str:
    """``PATH: reason`` for the user, without Python's ``[Errno N]`` decoration."""
    if exc.filename is None or not exc.strerror:
        return str(exc)
    return f"{exc.filename}: {exc.strerror}"


if __name__ == "__main__":
    sys.exit(main())
