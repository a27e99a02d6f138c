"""Whole-colon coverage maps: one reconstruction in, per-segment coverage out (``colonbench map``)."""
