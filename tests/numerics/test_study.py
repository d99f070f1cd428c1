"""`python -m numerics.study --quick` writes the summary with the required columns, reproduces the
paper's Eq. 11–12 within their bounds, and every form's evaluation error is within its bound."""

import csv

from numerics import forms
from numerics.study import main


def test_quick_study_writes_summary_plots_and_report(tmp_path):
    assert main(["--quick", "--out", str(tmp_path)]) == 0
    rows = list(csv.DictReader(open(tmp_path / "summary.csv")))
    required = {"form", "resolution", "offset_px", "anisotropy", "max_abs_power_err", "bound"}
    assert required <= set(rows[0])
    assert {r["form"] for r in rows} >= set(forms.FORMS) | {"paper_eq11_global",
                                                             "paper_eq12_local"}
    for r in rows:
        if r["bound"]:  # half-precision rows (FORM@DTYPE) measure total error only
            assert float(r["max_abs_power_err"]) <= float(r["bound"]), r
    assert {"difference@float16", "local_corner@bfloat16"} <= {r["form"] for r in rows}
    by = {r["form"]: r for r in rows if r["form"].startswith("paper")}
    assert float(by["paper_eq11_global"]["max_abs_power_err"]) > 0.5  # cancellation is real
    for name in ("power_err_vs_resolution.png", "power_err_vs_offset_px.png",
                 "power_err_vs_anisotropy.png", "cost_vs_error.png", "cost.csv", "REPORT.md"):
        assert (tmp_path / name).stat().st_size > 0
