import dataclasses
import os
import re

import matplotlib.image
import numpy as np
import pytest

import lgs_jax
from lgs_jax import cli, video
from lgs_jax.cli import fit as fit_cmd, main


# The default scene's renders here are 64x36 with the default backend, or 32x18 with `brute`:
# one compile of each (and of the pair count) serves every test of a worker that renders.


def test_render_default_scene_writes_png(tmp_path, capsys):
    out = tmp_path / "x.png"
    assert main(["render", "--width", "64", "--height", "36", "--out", str(out)]) == 0
    img = matplotlib.image.imread(out)
    assert img.shape[:2] == (36, 64)
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


def _error_line(capsys):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err  # one line, no traceback
    return err


@pytest.mark.parametrize("args,match", [
    (["--width", "0"], "--width: must be >= 1, got 0"),
    (["--height", "-3"], "--height: must be >= 1, got -3"),
    (["--width", "abc"], "--width: expected an integer, got 'abc'"),
    (["--view", "-1"], "--view: must be >= 0, got -1"),
    (["--background", "nan", "0", "0"], "--background: must be finite, got 'nan'"),
    (["--backend", "cuda"], "--backend: invalid choice: 'cuda'"),
])
def test_bad_option_values_are_usage_errors(capsys, args, match):
    with pytest.raises(SystemExit) as exit_:
        main(["render", *args])
    assert exit_.value.code == 2
    assert match in _error_line(capsys)


@pytest.mark.parametrize("args,match", [
    (["--view", "8"], "--view: 8 is out of range: the default scene has 8 orbit views (0..7)"),
    (["--view", "99"], "--view: 99 is out of range"),
    (["--out", "x.npy"], "--out: x.npy: extension '.npy' is not an image format"),
    (["--out", "x.exr"], "extension '.exr' is not an image format"),
    (["--out", "x"], "extension '(none)'"),
    (["--out", "{tmp}/missing/x.png"], "directory {tmp}/missing does not exist"),
    (["--out", "{tmp}"], "extension"),
    (["{tmp}"], "scene: {tmp}: not a file"),
    (["{tmp}/missing.ply"], "scene: {tmp}/missing.ply: no such file"),
    (["--cameras", "{tmp}/none.json"], "--cameras: {tmp}/none.json: no such file"),
    (["{ply}"], "--cameras: needed to render a scene file"),
])
def test_bad_command_lines_exit_2_with_one_line(tmp_path, capsys, args, match):
    ply = tmp_path / "s.ply"
    lgs_jax.save_ply(ply, lgs_jax.default_scene())
    fill = lambda s: s.format(tmp=tmp_path, ply=ply)
    assert main(["render", *map(fill, args)]) == 2
    assert fill(match) in _error_line(capsys)


def test_unwritable_out_directory_is_refused_before_rendering(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(os, "access", lambda path, mode: False)  # tests run as root
    monkeypatch.setattr(lgs_jax, "render", lambda *a, **k: pytest.fail("rendered"))
    assert main(["render", "--out", str(tmp_path / "x.png")]) == 2
    assert "not writable" in _error_line(capsys)


@pytest.mark.parametrize("args,match", [
    (["view", "--port", "70000"], "--port: must be from 1 to 65535, got 70000"),
    (["fit", "--data", "{tmp}", "--out", "{tmp}/run", "--viewer-port", "0"],
     "--viewer-port: must be from 1 to 65535, got 0"),
    (["fit", "--data", "{tmp}", "--out", "{tmp}/run", "--seed", "-1"],
     "--seed: must be >= 0, got -1"),
    (["fit", "--data", "{tmp}", "--out", "/proc/lgs_jax_run"], "--out: /proc/lgs_jax_run: "
                                                               "cannot write there"),
    (["fit", "--data", "{tmp}", "--out", "{ply}"], "--out: {ply} exists and is not a directory"),
    (["render", "--out", "/proc/lgs_jax.png"], "--out: /proc/lgs_jax.png: not writable"),
    (["video", "--out", "/proc/lgs_jax.mp4"], "--out: /proc/lgs_jax.mp4: not writable"),
    (["eval", "{ply}", "--data", "{tmp}", "--out", "{ply}"], "--out: {ply} is a file, not a "
                                                              "folder"),
    (["eval", "{ply}", "--data", "{tmp}", "--out", "/proc/lgs_jax_eval"],
     "--out: /proc/lgs_jax_eval: cannot make the folder"),
])
def test_ports_seeds_and_outputs_are_checked_before_any_work(tmp_path, capsys, monkeypatch,
                                                            args, match):
    """Exit code 2 and one line, before anything is loaded, rendered or trained."""
    from lgs_jax import train

    for owner, name in ((lgs_jax, "load_ply"), (lgs_jax, "default_scene"), (lgs_jax, "render"),
                        (train, "fit"), (train, "evaluate")):
        monkeypatch.setattr(owner, name, lambda *a, **k: pytest.fail("work started"))
    ply = tmp_path / "s.ply"
    ply.write_text("not read")
    fill = lambda s: s.format(tmp=tmp_path, ply=ply)
    try:
        code = main([fill(a) for a in args])
    except SystemExit as e:
        code = e.code
    assert code == 2
    assert fill(match) in _error_line(capsys)


def test_float64_scenes_render_as_float32_with_a_note(tmp_path, capsys):
    """Where JAX runs without float64 (the command line's default), a float64 PLY is cast."""
    import jax

    from lgs_jax.cli.args import load_scene

    ply = tmp_path / "s64.ply"
    g = lgs_jax.default_scene()
    lgs_jax.save_ply(ply, jax.tree.map(lambda x: np.asarray(x, np.float64), g))
    before = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", False)
    try:
        scene = load_scene(str(ply))
    finally:
        jax.config.update("jax_enable_x64", before)
    assert scene.means.dtype == np.float32 and scene.num == g.num
    np.testing.assert_array_equal(scene.means, np.asarray(g.means, np.float32))
    assert "holds float64 values; rendering them as float32 (JAX_ENABLE_X64=1" in \
        capsys.readouterr().err


def test_a_ply_given_as_cameras_is_named(tmp_path, capsys):
    ply = tmp_path / "s.ply"
    lgs_jax.save_ply(ply, lgs_jax.default_scene())
    assert main(["render", str(ply), "--cameras", str(ply), "--out", str(tmp_path / "x.png")]) == 1
    assert f"{ply}: is a PLY file, not a cameras file" in _error_line(capsys)


def test_the_viewer_refuses_ports_out_of_range():
    from lgs_jax import viewer

    with pytest.raises(ValueError, match="port: expected a TCP port from 1 to 65535, got 70000"):
        viewer.serve(None, [lgs_jax.default_camera()], port=70000)


@pytest.mark.parametrize("content,size,match", [
    ("[{", [], "not valid JSON"), ('[{"fx": "abc"}]', [], "camera 0: missing 'rotation'"),
    ('{"camera_angle_x": 0.7, "frames": []}', [], "'frames' is empty"),
    ('{"camera_angle_x": 0.7, "frames": []}', ["--width", "8"], "'frames' is empty"),
    ('{"camera_angle_x": 0.7, "frames": []}', ["--width", "8", "--height", "8"],
     "holds no cameras"),
    ("[]", [], "holds no cameras"),
])
def test_bad_camera_files_give_one_line(tmp_path, capsys, content, size, match):
    path = tmp_path / "cams.json"
    path.write_text(content)
    code = main(["render", "--cameras", str(path), "--out", str(tmp_path / "x.png"), *size])
    assert code == (2 if match == "holds no cameras" else 1)
    assert match in _error_line(capsys)


def test_malformed_ply_gives_one_line_and_debug_the_traceback(tmp_path, capsys):
    ply = tmp_path / "bad.ply"
    ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex -1\nend_header\n")
    cams = tmp_path / "cams.json"
    cams.write_text("[]")
    args = ["render", str(ply), "--cameras", str(cams), "--out", str(tmp_path / "x.png")]
    assert main(args) == 1
    assert f"{ply}: line 3: 'element vertex -1': the vertex count" in _error_line(capsys)
    with pytest.raises(lgs_jax.PlyError):
        main(args + ["--debug"])


def test_render_help_lists_backends_outputs_and_defaults(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["render", "--help"])
    assert exit_.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for backend in ("brute", "reference", "tiles", "pallas", "pallas_vanilla"):
        assert backend in text
    for phrase in ("default: the fastest exact one", "default: out.png", ".png/.jpg", "exit code 2",
                   "crop its centre", "compilation separately"):
        assert phrase in text, phrase


def test_render_runs_once_reports_compile_time_and_interpret_mode(tmp_path, capsys,
                                                                 monkeypatch):
    calls = []

    def once(*args, **kwargs):
        calls.append(kwargs["backend"])
        out = real(*args, **kwargs)
        from lgs_jax.backends.pallas import PallasStats

        interpreted = PallasStats(strip_pairs=0, pairs_walked=0, row_overflow=False,
                                  kernel="localgs-triton", interpreted=True)
        return dataclasses.replace(out, stats=dataclasses.replace(out.stats,
                                                                  backend_stats=interpreted))

    real = lgs_jax.render
    monkeypatch.setattr(lgs_jax, "render", once)
    out = tmp_path / "x.jpg"
    assert main(["render", "--width", "32", "--height", "18", "--out", str(out),
                 "--backend", "brute"]) == 0
    assert calls == ["brute"]
    text = capsys.readouterr().out
    assert re.search(r"time: [\d.]+ s, of which [\d.]+ s compiling", text)
    assert "interpret mode" in text
    assert matplotlib.image.imread(out).shape[:2] == (18, 32)


def test_render_passes_the_convention_and_antialiasing(tmp_path, monkeypatch):
    # the configuration the command passes is recorded; the render itself runs the default
    # one (what each configuration renders is tests/backends' to check): the 32x18 `brute`
    # program test_render_runs_once_reports_compile_time_and_interpret_mode compiled
    configs, real = [], lgs_jax.render
    monkeypatch.setattr(lgs_jax, "render", lambda *a, **k: configs.append(k["config"]) or real(
        *a, **dict(k, config=lgs_jax.RasterConfig())))
    out = str(tmp_path / "x.png")
    for flags in ([], ["--convention", "gsplat", "--antialiased"]):
        assert main(["render", "--width", "32", "--out", out, "--backend", "brute"] + flags) == 0
    assert configs == [lgs_jax.RasterConfig(),
                       lgs_jax.RasterConfig("gsplat", antialiased=True)]


def test_render_writes_the_depth_or_the_alpha(tmp_path):
    out = lgs_jax.render(lgs_jax.default_scene(), lgs_jax.default_camera(None, 64, 36))
    for output in ("depth", "alpha"):
        path = tmp_path / f"{output}.png"
        assert main(["render", "--width", "64", "--output", output, "--out", str(path)]) == 0
        written = np.round(matplotlib.image.imread(path)[..., :3] * 255).astype(np.uint8)
        np.testing.assert_array_equal(written, video.frame_pixels(out, output))


def test_one_size_keeps_the_aspect_ratio(tmp_path):
    out = tmp_path / "x.png"
    assert main(["render", "--view", "0", "--width", "64", "--out", str(out)]) == 0
    assert matplotlib.image.imread(out).shape[:2] == (36, 64)  # 16:9


def test_readme_test_command_is_what_ci_runs():
    root = os.path.join(os.path.dirname(__file__), "..")
    readme = open(os.path.join(root, "README.md")).read()
    ci = open(os.path.join(root, ".ci", "run")).read().strip().splitlines()
    command = readme.split("Run the tests")[1].split("```bash\n")[1].split("\n")[0]
    assert command == ". .venv/bin/activate && python -m pytest -n 2"
    # CI runs the README's command (the default set) and nothing after it; the README names the
    # slow set for those changing a kernel.
    assert ci[-1] == "python -m pytest -n 2"
    assert not any("-m slow" in line for line in ci if not line.startswith("#"))
    assert "`python -m pytest -n 2 -m slow`" in readme


def test_commands_use_the_persistent_compile_cache(tmp_path, monkeypatch):
    """The command line turns JAX's persistent compilation cache on (LGS_JAX_CACHE, "" for off)
    for every program, however quick its compile, capped and so locked (shared safely), and
    keeps a folder the caller configured (here: the test session's) with the caller's
    settings."""
    import jax

    from lgs_jax.cli import use_compile_cache

    session = jax.config.jax_compilation_cache_dir
    least = jax.config.jax_persistent_cache_min_compile_time_secs
    assert session and use_compile_cache() == session
    try:
        jax.config.update("jax_compilation_cache_dir", None)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)  # JAX's default
        monkeypatch.setenv("LGS_JAX_CACHE", "")
        assert use_compile_cache() is None and not jax.config.jax_compilation_cache_dir
        assert jax.config.jax_persistent_cache_min_compile_time_secs == 1.0
        monkeypatch.setenv("LGS_JAX_CACHE", str(tmp_path / "cache"))
        assert use_compile_cache() == str(tmp_path / "cache")
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "cache")
        assert jax.config.jax_persistent_cache_min_compile_time_secs == 0
        assert jax.config.jax_compilation_cache_max_size == cli.commands.CACHE_MAX_BYTES
    finally:
        jax.config.update("jax_compilation_cache_dir", session)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", least)


@pytest.mark.parametrize("flags,want", [([], None), (["--no-compile-ahead"], "off"),
                                        (["--compile-ahead-process"], "process"),
                                        (["--compile-ahead", "thread"], "thread")])
def test_fit_compile_ahead_flags(flags, want):
    args = cli.parser().parse_args(["fit", "--data", "d", "--out", "o", *flags])
    assert fit_cmd.config_of(args).compile_ahead == want


def _fit_parser():
    import argparse

    sub = next(a for a in cli.parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices["fit"]


def _changed(o, default):
    """A value of option `o`'s field other than `default` that its bounds allow."""
    import typing

    from lgs_jax.train.options import split_optional

    t, _ = split_optional(o.type)
    meta = o.field.metadata
    if t is bool:
        return not default
    if typing.get_origin(t) is typing.Literal or meta.get("choices"):
        known = typing.get_args(t) or meta["choices"]
        return next((v for v in known if v != default), default)
    if t is str:
        return f"{o.dest}-x"
    if typing.get_origin(t) is tuple:
        return (1, 2, 3, 4)
    low, high = meta.get("low"), meta.get("high")
    base = default if default is not None else (low or 0) + 1
    value = t(base + 1) if t is int else base * 0.5 + 0.25
    return value if high is None or value <= high else t(high - (high - (low or 0)) / 2)


def test_fit_options_and_fit_config_cannot_drift():
    """The fit command line is FitConfig's: every field (its Recipe's and the strategies'
    included) has an option of its name, every option sets a field (or is in one of
    lgs_jax.cli.fit's tables: ALIASES, DERIVED, CLI_ONLY), the defaults agree, and the options
    of a configuration with every field changed parse back to that configuration."""
    import typing

    from lgs_jax import train

    fit = _fit_parser()
    flags = {f for a in fit._actions for f in a.option_strings} - {"-h", "--help"}
    config, strategy = fit_cmd.config_options(), fit_cmd.strategy_options()
    made = {o.flag for o in config + strategy} | {"--strategy"}
    negated = {"--no-" + o.flag[2:] for o in config + strategy if o.type is not bool
               and typing.get_args(o.type) and bool in typing.get_args(o.type)}
    negated |= {"--no-" + o.flag[2:] for o in strategy if o.type is bool}
    assert flags == made | negated | set(fit_cmd.ALIASES) | set(fit_cmd.CLI_ONLY)
    fields = {f.name for f in dataclasses.fields(train.FitConfig)} - {"recipe", "strategy"}
    fields |= {f.name for f in dataclasses.fields(train.Recipe)}
    assert {o.dest for o in config} == fields and len(config) == len(fields)
    for cls in train.STRATEGIES.values():
        names = {f.name for f in dataclasses.fields(cls)}
        assert names <= {o.dest for o in strategy} | set(fit_cmd.DERIVED)
    dests = [o.dest for o in config + strategy]
    assert len(dests) == len(set(dests))  # one option per name
    minimal = ["fit", "--data", "d", "--out", "o"]
    args = cli.parser().parse_args(minimal)
    assert fit_cmd.config_of(args) == train.FitConfig(data="d", out="o")
    for o in config:
        want = o.field.default if o.field.default is not dataclasses.MISSING else getattr(
            args, o.dest)
        assert getattr(args, o.dest) == want, o.flag
    assert all(getattr(args, o.dest) is None for o in strategy)  # the strategy's own
    for name, cls in train.STRATEGIES.items():
        top = {o.dest: _changed(o, o.field.default) for o in config if o.path[0] != "recipe"}
        top.update(data="d", out="o", resume=True, overwrite=False, devices=2,
                   gaussian_devices=1)  # Gaussian parallel refuses devices > 1: below
        recipe = train.Recipe(**{o.dest: _changed(o, o.field.default) for o in config
                                 if o.path[0] == "recipe"} | dict(batch=4))
        fields = {f.name: _changed(next(o for o in strategy if o.dest == f.name), f.default)
                  for f in dataclasses.fields(cls) if f.name not in fit_cmd.DERIVED}
        fields |= {f: top[src] for f, src in fit_cmd.DERIVED.items() if f in
                   {g.name for g in dataclasses.fields(cls)}}
        changed = train.FitConfig(**top, recipe=recipe, strategy=cls(**fields))
        words = fit_cmd.argv(changed)
        assert fit_cmd.config_of(cli.parser().parse_args(["fit"] + words)) == changed, name
        assert changed != train.FitConfig(data="d", out="o")
    sharded = train.FitConfig(data="d", out="o", gaussian_devices=2)
    assert fit_cmd.config_of(cli.parser().parse_args(["fit"] + fit_cmd.argv(sharded))) == sharded


def test_fit_compile_ahead_flags_exclude_each_other(capsys):
    with pytest.raises(SystemExit):
        cli.parser().parse_args(["fit", "--data", "d", "--out", "o", "--no-compile-ahead",
                                  "--compile-ahead-process"])
    assert "not allowed with" in capsys.readouterr().err
