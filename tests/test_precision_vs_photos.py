"""benchmarks/precision_vs_photos.py without training: its fit command lines are `fit`'s (the
form, the precision and --shrink reach the configuration), and its summary pairs the forms, and
float64 training with float32's, by seed."""

import pytest

from benchmarks import precision_vs_photos as pvp
from lgs_jax import cli, train
from lgs_jax.cli import fit as fit_cmd


@pytest.mark.parametrize("scene,downscale,steps", [("lego_train", 1, 7000), ("skull", 2, 3000)])
def test_each_run_is_a_fit_command_line_of_its_form(scene, downscale, steps):
    args = pvp.parse(["--data-root", "/data", "--backend", "tiles", "--fit-args", "--sh-degree 1"])
    words = pvp.fit_words(args, scene, "global", 3, "/runs/x")
    config = fit_cmd.config_of(cli.parser().parse_args(words))
    assert config.recipe == train.Recipe(alpha_form="global", sh_degree=1)
    assert (config.data, config.out, config.seed, config.downscale, config.steps,
            config.backend) == (f"/data/{scene}", "/runs/x", 3, downscale, steps, "tiles")
    assert config.eval_every == config.checkpoint_every == pvp.BIG and config.overwrite
    assert pvp.fit_words(pvp.parse(["--steps", "50"]), scene, "local", 0, "o")[
        words.index("--steps") + 1] == "50"
    small = fit_cmd.config_of(cli.parser().parse_args(pvp.fit_words(
        pvp.parse(["--precision", "float64", "--shrink", "4"]), scene, "local", 0, "o")))
    assert (small.precision, small.downscale) == ("float64", 4 * downscale)
    assert [label for label, _, _ in pvp.evals(pvp.parse(["--shrink", "4"]), scene)] == [
        label + "/4" for label, _, _ in pvp.SCENES[scene]["evals"]]


def _row(form, seed, psnr, ev="200x200"):
    return dict(scene="lego_train", form=form, seed=seed, eval=ev, psnr=psnr, ssim=0.9,
                psnr_f64=psnr + 0.01, ssim_f64=0.9, psnr_vs_f64=100.0, max_abs_vs_f64=0.002,
                over_1_255=0.0, device="cpu", backend="tiles")


def test_rows_are_kept_as_runs_end_and_summarised_paired_by_seed(tmp_path, capsys):
    out = str(tmp_path)
    (tmp_path / "other").mkdir()
    pvp.keep(out, [_row("local", 0, 30.0), _row("global", 0, 29.0)])
    pvp.keep(out, [_row("local", 1, 31.0), _row("global", 1, 30.5)])
    pvp.keep(out, [_row("global", 1, 30.0)])  # a rerun replaces its row
    pvp.keep(out, [dict(scene="lego_train", form="difference", seed=0, eval="200x200",
                        error="fit: boom")])
    rows = pvp.read_csv(str(tmp_path / "results.csv"))
    assert [(r["form"], r["seed"], r["psnr"]) for r in rows] == [
        ("local", "0", "30.0"), ("global", "0", "29.0"), ("local", "1", "31.0"),
        ("global", "1", "30.0"), ("difference", "0", "")]
    capsys.readouterr()
    assert pvp.summary(pvp.parse(["--out", out])) == 0
    text = (tmp_path / "summary.md").read_text()
    assert text.strip() == capsys.readouterr().out.strip()
    lines = {line.split(" | ")[2]: line for line in text.splitlines() if "| lego_train" in line}
    assert "| 2 | 30.500 ± 0.707 | 0.9000 ± 0.0000 | - |" in lines["local"]
    # global − local per seed: −1.0, −1.0: mean −1, standard error 0
    assert "| 2 | 29.500 ± 0.707 | 0.9000 ± 0.0000 | -1.000 ± 0.000 |" in lines["global"]
    assert "difference" not in lines and "1 rows failed: lego_train difference seed 0" in text
    other = tmp_path / "other"  # another call's rows, summarised with these
    pvp.keep(str(other), [_row("local", 2, 32.0)])
    assert pvp.summary(pvp.parse(["--out", str(other), "--summary", "--inputs",
                                  str(tmp_path / "results.csv"),
                                  str(other / "results.csv")])) == 0
    assert "| lego_train | 200x200 | local | float32 | 3 | 31.000 ± 1.000 |" in (
        other / "summary.md").read_text()
    # float64 training: its own image is the f64 render (psnr_f64), paired with float32's
    pvp.keep(out, [dict(_row("local", s, 0.0), precision="float64", psnr_f64=p)
                   for s, p in ((0, 30.5), (1, 31.25))])
    assert pvp.summary(pvp.parse(["--out", out])) == 0
    assert "| local | float64 | 2 | 0.000 ± 0.000 | 0.9000 ± 0.0000 | - | +0.375 ± 0.125 |" in (
        tmp_path / "summary.md").read_text()
