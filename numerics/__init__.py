"""Numerics study of the Gaussian exponent in float32 vs float64 (issue: numerics/ study).

Not yet written: this package is installed beside lgs_jax so that the study can land here.
"""
