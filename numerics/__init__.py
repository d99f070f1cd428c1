"""Numerics study of the Gaussian exponent in float32 vs float64 (Local-GS Sec. III-B.4).

  `numerics.forms`         the exponent forms (difference, global, local_corner, local_center,
                           principal_axes; whitened) with derived bounds on their float
                           evaluation error;
  `numerics.study`         the exponent-level study, `python -m numerics.study [--quick] --out DIR`
                           (sweeps over resolution, centre offset, anisotropy and opacity; the
                           paper's Eq. 11–12 reproduced; half precision; the centre sweep and the
                           costs; summary.csv, centre.csv, cost*.csv, plots, REPORT.md written by
                           `numerics.report`; the sweep's design in `numerics.sampling`);
  `numerics.split`         the split centre μ = hi + lo from float32 parameters (the library's
                           error-free transformations, lgs_jax.twofloat), the plain float32
                           centre, and the offsets taken from them;
  `numerics.axes`          the principal axes of the projected covariance in float32, from its
                           factor J·W·R·S;
  `numerics.centre`        the centre floor from float32 world-space parameters, the centre in
                           one float32 number against the split centre (the library's) and
                           the whitened principal axes,
                           `python -m numerics.centre [--quick] --out DIR`;
  `numerics.cost`          each form's evaluation cost and the per-Gaussian work upstream,
                           `python -m numerics.cost`;
  `numerics.render_study`  the rendering-level study on real scenes up to 8K,
                           `python -m numerics.render_study`.

Results of the full runs are in numerics/results/ (REPORT.md; render/ for the rendering level);
notebooks/precision.ipynb walks through them; `python -m paper_figs` draws them.
"""
