"""hiros_convert: other body-tracking file formats into the skeleton model and into recordings."""

from hiros_convert._frames import CameraStream
from hiros_convert.convert import FORMATS, convert, detect_format, read_streams
from hiros_convert.generic_csv import read_generic_csv
from hiros_convert.k4abt_json import read_k4abt_json
from hiros_convert.multitrack import read_multitrack_csv
from hiros_convert.unipd import read_unipd_csv

__all__ = [
    "FORMATS",
    "CameraStream",
    "convert",
    "detect_format",
    "read_generic_csv",
    "read_k4abt_json",
    "read_multitrack_csv",
    "read_streams",
    "read_unipd_csv",
]
