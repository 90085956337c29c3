"""The ``hiros`` command line: one subcommand per module in ``hiros_cli.commands``."""
