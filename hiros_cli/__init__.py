"""The ``hiros`` command line: one subcommand per module in ``hiros_cli.commands``."""

from hiros_cli.main import main

__all__ = ["main"]
