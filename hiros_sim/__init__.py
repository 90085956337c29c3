"""hiros_sim: semi-synthetic multi-camera Azure Kinect recordings from real mocap, with truth."""

from hiros_sim.bvh import BvhMotion, read_bvh
from hiros_sim.mapping import map_to_azure
from hiros_sim.noise import CONFIDENCE_OF_LEVEL
from hiros_sim.output import load_truth, save_truth, write_recording
from hiros_sim.params import SimParams, default_bvh_files
from hiros_sim.presets import PRESETS, Preset, preset_params
from hiros_sim.sample import sample_params
from hiros_sim.simulate import SimResult, Truth, simulate

__all__ = [
    "CONFIDENCE_OF_LEVEL",
    "PRESETS",
    "BvhMotion",
    "Preset",
    "SimParams",
    "SimResult",
    "Truth",
    "default_bvh_files",
    "load_truth",
    "map_to_azure",
    "preset_params",
    "read_bvh",
    "sample_params",
    "save_truth",
    "simulate",
    "write_recording",
]
