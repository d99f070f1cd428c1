"""paper_figs: the per-tile culling counts are the renderer's, and a figure whose recorded CSV
is missing is skipped with a message naming the file and the command that writes it."""

import numpy as np

from paper_figs import culling, make_figs
from tests import scenes


def test_strip_counts_match_the_tiles_backend_stats():
    g = scenes.cast(scenes.scene(3, kinds=("normal", "needle", "tiny", "huge_far")), np.float32)
    cam = scenes.camera()
    pairs, strips = culling.strip_counts(g, cam)
    stats = scenes.render(g, cam, "tiles", scenes.lgs_jax.RasterConfig()).stats
    assert pairs.shape == (2, 3)  # 40x24: 3x2 tiles
    assert pairs.sum() == int(stats.pairs_required)
    assert strips.sum() == int(stats.backend_stats.strip_pairs)
    assert np.all(strips <= 8 * pairs)


def test_missing_csv_skips_its_figure(monkeypatch, capsys):
    drawn = []
    monkeypatch.setattr(make_figs, "FIGURES", {
        "x.png": (lambda: drawn.append("x"), ["bench_results/no_such.csv"], "the command")})
    assert make_figs.main() == 0
    assert not drawn
    assert capsys.readouterr().out.strip() == (
        "skipped x.png: missing bench_results/no_such.csv (written by: the command)")
