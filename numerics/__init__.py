"""Numerics study of the Gaussian exponent in float32 vs float64 (Local-GS Sec. III-B.4).

So far: `numerics.forms`, the five exponent forms (difference, global, local_corner, local_center,
principal_axes) with derived bounds on their float evaluation error, tested in
tests/test_numerics_forms.py. The sweeps, rendering-level study, `python -m numerics.study`,
REPORT.md and notebook are still to come.
"""
