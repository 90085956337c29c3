"""hiros_convert: other body-tracking file formats into the skeleton model and into recordings."""

from hiros_convert.multitrack import read_multitrack_csv

__all__ = ["read_multitrack_csv"]
