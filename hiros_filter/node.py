"""``ros2 run hiros filter``: /hiros/optimizer -> Filter.update -> /hiros/filter."""

from __future__ import annotations

from dataclasses import dataclass

from hiros_filter.filter import Filter, FilterParams
from hiros_ros import stage_main

__all__ = ["LIVE", "FilterNodeParams", "main"]

LIVE = (
    "cutoff_frequency",
    "jerk_spectral_density",
    "measurement_noise",
    "orientation_cutoff_frequency",
)
"""Parameters applied while the node runs (``Filter.set_params``); the rest are read-only."""


@dataclass
class FilterNodeParams(FilterParams):
    """The filter's parameters plus the node's topics."""

    input_topic: str = "/hiros/optimizer"
    output_topic: str = "/hiros/filter"
    input_qos: str = "reliable"


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hiros filter``."""
    stage_main("filter", FilterNodeParams, Filter, live=LIVE, args=args)
