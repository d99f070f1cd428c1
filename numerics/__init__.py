"""Numerics study of the Gaussian exponent in float32 vs float64 (Local-GS Sec. III-B.4).

So far: `numerics.forms`, the five exponent forms (difference, global, local_corner, local_center,
principal_axes) with derived bounds on their float evaluation error, and the exponent-level study
`python -m numerics.study [--quick] --out DIR` (sweeps over resolution, centre offset and
anisotropy; the paper's Eq. 11–12 reproduced; summary.csv, plots, REPORT.md; results of the full
run in numerics/results/). Still to come: the rendering-level study (real scenes at 4K/8K), the
cost side, and notebooks/precision.ipynb.
"""
