"""Data-parallel training (`fit(..., devices=N)`, `step.over_views`): on two CPU devices
(`--xla_force_host_platform_device_count`, set before JAX starts, so in a child process) a run
with refinements follows the one-device run to float rounding (the gradients' sum is taken in
another order), compiles its step no more often, and repeats itself to the bit, watched or
not (`fit`'s `watch` gets one device's copy of the pool), the views' own parameters
(`view_params`: poses and colour corrections) optimized alike; bad device counts are refused by
name."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from lgs_jax import train

CHILD = textwrap.dedent("""
    import dataclasses, json, os, sys
    import jax, numpy as np
    import lgs_jax
    from lgs_jax import train
    compiles = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, seconds, fun_name="", **_: compiles.append(fun_name)
        if event == "/jax/core/compile/backend_compile_duration" else None)
    d = lgs_jax.load_dataset(sys.argv[1], downscale=32)
    keep = np.linspace(0, len(d.points) - 1, 200).astype(int)
    d = dataclasses.replace(d, points=d.points[keep], colors=d.colors[keep], train=d.train[:4],
                            test=d.test[:1])
    strategy = train.DefaultStrategy(refine_start_iter=2, refine_every=3, grow_grad2d=1e-4,
                                     prune_opa=0.02)
    recipe = train.Recipe(batch=2, pose_opt=True, color_opt=True, app_opt=True)
    out, watched = {}, []
    watch = lambda step, g, m: watched.append(
        (step, len(g.means.devices()), int(np.isfinite(np.asarray(g.logit_opacities)).sum()),
         m["gaussians"]))
    for run, devices in (("one", 1), ("two", 2), ("again", 2)):
        before = len(compiles)
        config = train.FitConfig(data=d.path, out=os.path.join(sys.argv[2], run), steps=6,
                                 strategy=strategy, recipe=recipe, max_gaussians=512,
                                 pool_size=512, backend="reference", devices=devices,
                                 eval_every=100, checkpoint_every=100)
        result = train.fit(config, d, log=lambda m: None,
                           watch=watch if run == "again" else None, watch_every=0)
        rows = [json.loads(line) for line in open(os.path.join(sys.argv[2], run,
                                                               "metrics.jsonl"))]
        steps = [name for name in compiles[before:] if name == "jit(train_step)"]
        out[run] = dict(rows=[r for r in rows if "loss" in r], compiles=len(steps),
                        devices=result["devices"], psnr=result["heldout_psnr"])
    out["watched"] = watched
    print(json.dumps(out))
""")


@pytest.mark.slow  # CI time: tests/parallel runs several simulated devices in the default set
def test_two_devices_follow_one_and_repeat_themselves(data_dir, tmp_path):
    skull = os.path.join(data_dir, "skull")
    if not os.path.isdir(skull):
        pytest.skip("skull not found")
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2",
               JAX_PLATFORMS="cpu")
    done = subprocess.run([sys.executable, "-c", CHILD, skull, str(tmp_path)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    one, two, again = out["one"], out["two"], out["again"]
    assert (one["devices"], two["devices"]) == (1, 2)
    assert len(one["rows"]) == len(two["rows"]) == 6
    for a, b in zip(one["rows"][:2], two["rows"][:2]):  # the same start: the same loss
        assert b["loss"] == pytest.approx(a["loss"], rel=1e-6)
    for a, b in zip(one["rows"], two["rows"]):  # then the gradients' sums round apart
        assert a["gaussians"] == b["gaussians"]  # the same refinements
        assert b["loss"] == pytest.approx(a["loss"], rel=1e-3)
    assert two["psnr"] == pytest.approx(one["psnr"], abs=0.05)
    # one compile of the step each (the pairs need no growth here): none for new shardings
    assert one["compiles"] == two["compiles"] == 1 and again["compiles"] == 0
    strip = lambda rows: [{k: v for k, v in r.items() if k != "seconds"} for r in rows]
    assert strip(again["rows"]) == strip(two["rows"]) and again["psnr"] == two["psnr"]
    # the repeat was watched (which changed no bit): every step, one device's copy of the pool
    assert [w[0] for w in out["watched"]] == list(range(7))
    assert all(w[1] == 1 and w[2] == w[3] for w in out["watched"])
    assert [w[3] for w in out["watched"][1:]] == [r["gaussians"] for r in again["rows"]]


@pytest.mark.parametrize("devices,match", [
    (0, "devices: expected an int >= 1"), (64, "devices: expected an int from 1 to"),
    (True, "devices: expected an int")])
def test_bad_device_counts_are_refused(tmp_path, devices, match):
    with pytest.raises(ValueError, match=match):
        train.fit(train.FitConfig(data="unused", out=str(tmp_path / "o"), devices=devices,
                                  recipe=train.Recipe(batch=64)))


def test_the_batch_must_split_evenly():
    with pytest.raises(ValueError, match="devices: 2 devices split recipe.batch = 3 views "
                                         "unevenly"):
        train.FitConfig(data="unused", out="o", recipe=train.Recipe(batch=3), devices=2)


def test_a_run_on_several_devices_compares_its_checkpoint():
    # `--resume` compares the checkpoint's settings with this run's, the fields it predates
    # counted as the default recipe's (batch 1): which a run's devices need not split
    from lgs_jax.train import checkpoint

    config = train.FitConfig(data="unused", out="o", recipe=train.Recipe(batch=2), devices=2,
                             gaussian_devices=2)
    defaults = checkpoint.default_config(config)
    assert defaults["settings"]["batch"] == 1
    assert checkpoint.config_mismatch(checkpoint.config_of(config),
                                      checkpoint.config_of(config), defaults) is None
