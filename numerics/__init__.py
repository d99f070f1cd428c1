"""Numerics study of the Gaussian exponent in float32 vs float64 (Local-GS Sec. III-B.4).

  `numerics.forms`         the five exponent forms (difference, global, local_corner,
                           local_center, principal_axes) with derived bounds on their float
                           evaluation error;
  `numerics.study`         the exponent-level study, `python -m numerics.study [--quick] --out DIR`
                           (sweeps over resolution, centre offset, anisotropy and opacity; the
                           paper's Eq. 11–12 reproduced; half precision; summary.csv, plots,
                           REPORT.md);
  `numerics.cost`          each form's evaluation cost, `python -m numerics.cost`;
  `numerics.render_study`  the rendering-level study on real scenes up to 8K,
                           `python -m numerics.render_study`.

Results of the full runs are in numerics/results/ (REPORT.md; render/ for the rendering level);
notebooks/precision.ipynb walks through them.
"""
