"""hiros_calib: spatio-temporal camera calibration from people's own motion."""

from hiros_calib.sync import CameraClock, PairOffset, SyncParams, estimate_pair_offset, synchronise
from hiros_calib.tracks import BodyTrack, extract_tracks

__all__ = [
    "BodyTrack",
    "CameraClock",
    "PairOffset",
    "SyncParams",
    "estimate_pair_offset",
    "extract_tracks",
    "synchronise",
]
