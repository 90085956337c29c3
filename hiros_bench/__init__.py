"""Benchmarks behind ``hiros bench``: each prints its figures beside a baseline run alongside."""
