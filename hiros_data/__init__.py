"""hiros_data: the motion capture the bundled sample and ``hiros simulate`` are made from.

See README.md in this folder for the sources and licences. ``DATA_DIR`` is the folder.
"""

from pathlib import Path

__all__ = ["DATA_DIR"]

DATA_DIR = Path(__file__).resolve().parent
"""Folder of the bundled data files."""
