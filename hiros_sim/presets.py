"""Named sets of simulator knobs: the conditions a calibration or a stage must hold under.

Each preset changes a few ``SimParams`` fields and leaves every other at its default, so that a
benchmark can run one row per condition with default settings otherwise::

    for name, preset in PRESETS.items():
        result = simulate(preset_params(name, seed=seed, duration=30.0))

``all`` combines every single condition that fits one scene (one person, two cameras): per-host
log clocks, repeated Bandai-Namco motion, the 45° pair, the noisier SDK, 15 Hz and 5 % drops.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from types import MappingProxyType
from typing import TYPE_CHECKING

from hiros_core.errors import ConfigError
from hiros_sim.params import SimParams, default_bvh_files
from hiros_sim.shared import bandai_files

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["PRESETS", "Preset", "preset_params"]


@dataclass(frozen=True)
class Preset:
    """A named condition: a one-line description and the ``SimParams`` fields it sets."""

    description: str
    overrides: Mapping[str, object] = field(default_factory=dict)

    @property
    def needs_shared_data(self) -> bool:
        """Its clips come from the shared data folder (``hiros_sim.shared``), not the package."""
        return self.overrides.get("motion") == "bandai"


_HOST_CLOCKS = {"log_clock": "camera"}
_REPEATED = {"motion": "bandai", "loop_variation": 0.1}
_ONE_PERSON = {"n_people": 1}
_PAIR = {"setup": "pair", "n_cameras": 2, "walk_area": 0.3}
_NOISY = {
    "noise_base": 0.024,
    "noise_per_metre": 0.008,
    "occluded_gain": 4.0,
    "extremity_gain": 2.0,
    "bias_drift_time": 3.0,
    "noise_residual": 0.008,
}
_EXERCISE = {
    **_HOST_CLOCKS,
    **_ONE_PERSON,
    **_PAIR,
    "bvh_files": tuple(path for path in default_bvh_files() if "bend" in path),
    "loop_variation": 0.1,
    "max_time_offset": 1.5,
}
_RATE_15 = {"rate": 15.0}
_DROPS_5 = {"drop_rate": 0.05}
_CROSSING = {
    "n_people": 4,
    "lane_width": 0.45,
    "enter_leave": False,
    "bvh_files": default_bvh_files()[1:2],  # 131_02: the straightest walk (±7 cm sideways)
}

PRESETS: Mapping[str, Preset] = MappingProxyType(
    {
        "default": Preset("today's defaults: 3 cameras (room), 2 people walking, 30 Hz"),
        "host-clocks": Preset(
            "log times in each camera's own host clock (stamp + 20-30 ms), not one receiver's",
            _HOST_CLOCKS,
        ),
        "repeated-motion": Preset(
            "Bandai-Namco gestures and walks repeated all along, +-10 % speed per repetition "
            "(needs the shared data)",
            _REPEATED,
        ),
        "one-person": Preset("a single person", _ONE_PERSON),
        "two-cameras-45": Preset(
            "two cameras side by side, 40-50 deg apart, 1.3-1.5 m baseline", _PAIR
        ),
        "noisy-sdk": Preset(
            "noisier SDK: 2x joint noise, 4x on hidden joints, 2x more on hands, feet and "
            "face, biases drifting over 3 s, independent noise on top",
            _NOISY,
        ),
        "15hz": Preset("cameras at 15 Hz", _RATE_15),
        "drops-5": Preset("5 % of the frames dropped", _DROPS_5),
        "crossing-4": Preset(
            "four people walking to and fro in lanes 0.45 m apart, passing each other closely",
            _CROSSING,
        ),
        "walk-pair-host": Preset(
            "one person walking the bundled walk, looped to the frame, in and out of the "
            "45-deg pair's views, each camera on its own host",
            {**_HOST_CLOCKS, **_ONE_PERSON, **_PAIR},
        ),
        "crossing-host": Preset(
            "crossing-4 with each camera's log times on its own host clock: one walk looped by "
            "four people, whose motion correlates alike at many lags",
            {**_CROSSING, **_HOST_CLOCKS},
        ),
        "exercise-on-spot": Preset(
            "one person bending over and over on one spot (the bundled inertial-mocap bend, "
            "looped +-10 %) before the 45-deg pair, each camera on its own host, clocks within "
            "1.5 s: two Azure Kinects watching a strength exercise",
            _EXERCISE,
        ),
        "all": Preset(
            "one person repeating Bandai-Namco motion before the 45-deg pair, host clocks, "
            "noisy SDK, 15 Hz, 5 % drops (needs the shared data)",
            {
                **_HOST_CLOCKS,
                **_REPEATED,
                **_ONE_PERSON,
                **_PAIR,
                **_NOISY,
                **_RATE_15,
                **_DROPS_5,
            },
        ),
    }
)
"""Every preset by name, ``default`` first and ``all`` last."""


def preset_params(name: str, **overrides: object) -> SimParams:
    """``SimParams`` of the preset ``name``, then ``overrides`` (any ``SimParams`` field).

    Raises:
        ConfigError: an unknown preset or field, or a preset whose clips are absent (the
            Bandai-Namco motion needs the shared data; see ``hiros_sim.shared``).

    """
    if name not in PRESETS:
        msg = f"unknown simulator preset {name!r}; the presets are {', '.join(PRESETS)}"
        raise ConfigError(msg)
    known = {f.name for f in fields(SimParams)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        msg = f"SimParams has no field {', '.join(unknown)}"
        raise ConfigError(msg)
    params = replace(SimParams(), **{**PRESETS[name].overrides, **overrides})
    if params.motion == "bandai" and not params.bvh_files:
        bandai_files(params.n_people, params.seed)  # the clips are there, or a clear error now
    return params
