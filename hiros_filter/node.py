"""``ros2 run hiros filter``: /hiros/optimizer -> Filter.update -> /hiros/filter."""

from __future__ import annotations

from hiros_filter.filter import Filter, FilterParams
from hiros_ros import stage_main

__all__ = ["main"]


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hiros filter``."""
    stage_main(
        "filter",
        FilterParams,
        Filter,
        input_topic="/hiros/optimizer",
        output_topic="/hiros/filter",
        args=args,
    )
