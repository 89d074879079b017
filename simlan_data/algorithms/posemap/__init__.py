"""Pose mapping: landmarks of a person -> joint targets of the humanoid (pure numpy/torch)."""
