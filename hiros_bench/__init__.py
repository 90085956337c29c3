"""Benchmarks behind ``hiros bench``: each prints its figures beside a baseline run alongside."""

__all__ = ["SuiteFailedError"]


class SuiteFailedError(Exception):
    """A suite whose own verdict is a failure (it has printed why); ``hiros bench`` exits 1."""
