"""hiros_filter: causal smoothing of each person's joints, with velocities and accelerations."""

from hiros_filter.filter import Filter, FilterParams

__all__ = ["Filter", "FilterParams"]
