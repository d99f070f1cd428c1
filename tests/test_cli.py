import os

import matplotlib.image

from lgs_jax.cli import main


def test_render_default_scene_writes_png(tmp_path, capsys):
    out = tmp_path / "x.png"
    assert main(["render", "--width", "96", "--height", "54", "--out", str(out)]) == 0
    img = matplotlib.image.imread(out)
    assert img.shape[:2] == (54, 96)
    text = capsys.readouterr().out
    assert "4721 Gaussians" in text and "pairs" in text


def test_render_scene_with_cameras(tmp_path, data_dir):
    out = tmp_path / "g.png"
    root = os.path.join(data_dir, "guitar")
    assert main(["render", os.path.join(root, "guitar.ply"), "--cameras",
                 os.path.join(root, "orbit_cameras.json"), "--view", "3", "--width", "64",
                 "--height", "36", "--out", str(out)]) == 0
    assert matplotlib.image.imread(out).shape[:2] == (36, 64)


def test_info_reports_non_finite(data_dir, capsys):
    assert main(["info", os.path.join(data_dir, "guitar", "guitar.ply")]) == 0
    text = capsys.readouterr().out
    assert "90854 Gaussians" in text and "667" in text
