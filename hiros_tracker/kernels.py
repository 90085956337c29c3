"""The tracker's compiled per-frame kernels (numba), one front door for the modules by concept.

A tracker frame holds a handful of people and 32 joints: numpy's per-call overhead (1-5 us)
dominated the arithmetic, so each step of ``Tracker._process`` that took many small numpy calls
is one loop nest. The kernels live by concept:

- ``association``: costs of every (track, detection) pair, the gate, the solver's pairs;
- ``labels``: detections put in their tracks' labelling, tracks and outputs relabelled;
- ``track_update``: a hit track's pose smoothed and its velocities refitted, expiry;
- ``facing``: the evidence on each track's facing, and tracks found reversed turned;
- ``hit``: one frame's pairs through all of these (``hit_frame``);
- ``rigid``: detections moved into the world frame (the correction).

Their arguments are the named bundles of ``kernel_args``. Each kernel's docstring states its
maths; ``test/hiros_tracker/test_kernel_reference.py`` restates the association costs, the gate
and the velocity fit in numpy and holds the kernels to them on random inputs. Compiled lazily
on first call and cached on disk (``cache=True``): importing this module compiles nothing.
"""

from __future__ import annotations

from hiros_tracker.association import (
    INFEASIBLE,
    frame_costs,
    frame_pairs,
    gate_costs,
    masked_positions,
    match_costs,
)
from hiros_tracker.facing import turn_facing
from hiros_tracker.hit import hit_frame
from hiros_tracker.labels import canonical_poses, hold_axes, label_frame, label_rows, relabel
from hiros_tracker.rigid import move_frame, moved_frame
from hiros_tracker.track_update import fold_hits, live_tracks

__all__ = [
    "INFEASIBLE",
    "canonical_poses",
    "fold_hits",
    "frame_costs",
    "frame_pairs",
    "gate_costs",
    "hit_frame",
    "hold_axes",
    "label_frame",
    "label_rows",
    "live_tracks",
    "masked_positions",
    "match_costs",
    "move_frame",
    "moved_frame",
    "relabel",
    "turn_facing",
]
