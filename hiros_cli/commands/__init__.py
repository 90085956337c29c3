"""Subcommands of ``hiros``.

Each module defines ``HELP`` (one line), ``add_arguments(parser)`` and ``run(args) -> int``;
``hiros_cli.main`` lists them in ``COMMANDS``.
"""
