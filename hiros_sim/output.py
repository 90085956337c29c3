"""Writing a simulated recording to disk and reading its truth back.

A simulation folder holds:

====================  =================================================================
file                  what
====================  =================================================================
``recording.mcap``    Azure-driver ``visualization_msgs/MarkerArray`` on
                      ``/<cam>/body_tracking_data``, log time = arrival at the recorder
``truth.npz``         ``times (T,)`` reference seconds, ``positions (P, T, 32, 3)`` world
                      frame (float32), ``person_ids (P,)``, ``clip_names (P,)``,
                      ``cameras``, and one row per published skeleton: ``det_camera``
                      (index into ``cameras``), ``det_stamp_ns``, ``det_sdk_id``,
                      ``det_person`` (-1 = ghost); ``params`` (JSON of SimParams)
``calibration.yaml``  true camera poses and clocks (DESIGN.md calibration format)
====================  =================================================================
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import asdict
from pathlib import Path

import numpy as np

from hiros_core.calibration import save_calibration
from hiros_core.errors import RecordingError
from hiros_core.outputs import BAG_METADATA
from hiros_sim.simulate import SimResult, Truth

__all__ = ["load_truth", "save_truth", "write_recording"]

TRUTH_FILE = "truth.npz"
CALIBRATION_FILE = "calibration.yaml"
RECORDING_FILE = "recording.mcap"
SIMULATION_FILES = (RECORDING_FILE, BAG_METADATA, TRUTH_FILE, CALIBRATION_FILE)
"""What a simulation folder holds: all that ``hiros simulate --force`` may replace."""


def save_truth(result: SimResult, out_dir: str | Path) -> Path:
    """Write ``truth.npz`` and ``calibration.yaml`` into ``out_dir``; returns the folder."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cameras = list(result.camera_groups)
    det_camera, det_stamp, det_id, det_person = [], [], [], []
    for c, name in enumerate(cameras):
        for group, labels in zip(result.camera_groups[name], result.labels[name], strict=True):
            det_camera.extend([c] * len(group.skeletons))
            det_stamp.extend([group.stamp_ns] * len(group.skeletons))
            det_id.extend(s.id for s in group.skeletons)
            det_person.extend(labels.tolist())
    truth = result.truth
    np.savez_compressed(
        out / TRUTH_FILE,
        times=truth.times,
        positions=truth.positions.astype(np.float32),
        person_ids=truth.person_ids,
        clip_names=np.array(truth.clip_names, dtype=str),
        cameras=np.array(cameras, dtype=str),
        det_camera=np.array(det_camera, dtype=np.int32),
        det_stamp_ns=np.array(det_stamp, dtype=np.int64),
        det_sdk_id=np.array(det_id, dtype=np.int32),
        det_person=np.array(det_person, dtype=np.int32),
        params=np.array(json.dumps(asdict(result.params))),
    )
    save_calibration(result.calibration, out / CALIBRATION_FILE)
    return out


def write_recording(result: SimResult, out_dir: str | Path) -> Path:
    """Write the recording (MCAP), the truth and the calibration into ``out_dir``.

    Beside ``recording.mcap`` goes rosbag2's ``metadata.yaml``, so that the folder itself opens
    as a bag. An existing recording (and its ``metadata.yaml``) in the folder is replaced.

    Raises:
        RecordingError: the folder cannot be written.

    """
    from hiros_core.driver import group_to_driver_markers
    from hiros_core.recording import RecordingWriter

    out = save_truth(result, out_dir)
    recording = out / RECORDING_FILE
    for old in (recording, out / BAG_METADATA):
        old.unlink(missing_ok=True)
    # one time-ordered stream across cameras, by arrival at the recorder
    entries = [
        (int(receive), name, k)
        for name, groups in result.camera_groups.items()
        for k, receive in enumerate(result.receive_ns[name][: len(groups)])
    ]
    entries.sort()
    with RecordingWriter(recording, bag_metadata=True) as writer:
        for receive, name, k in entries:
            data = group_to_driver_markers(result.camera_groups[name][k])
            writer.write_marker_array(f"/{name}/body_tracking_data", data, receive)
    return out


def load_truth(sim_dir: str | Path) -> Truth:
    """Read ``truth.npz`` from a simulation folder (or the file itself).

    Positions are stored as float32 (sub-millimetre); they come back as float64.
    """
    path = Path(sim_dir)
    if path.is_dir():
        path = path / TRUTH_FILE
    try:
        with path.open("rb") as stream:  # closed here also when numpy gives up on it
            data = np.load(stream)
            if not isinstance(data, np.lib.npyio.NpzFile):  # a plain .npy array
                msg = "not an .npz archive"
                raise ValueError(msg)
            return Truth(
                times=data["times"].astype(float),
                positions=data["positions"].astype(float),
                person_ids=data["person_ids"].astype(np.int64),
                clip_names=tuple(str(n) for n in data["clip_names"]),
            )
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as exc:  # cut, damaged
        msg = f"cannot read simulation truth {path} (is it hiros simulate's?): {exc}"
        raise RecordingError(msg) from exc
