"""Benchmarks: the cost of one update by phase (``step``) and the paper's numbers (``paper``)."""
