"""lgs_jax.train.checkpoint: a checkpoint that cannot be resumed from (truncated, corrupted,
keys or arrays missing, values of the wrong kind, written for another step) is refused in one
line naming the file and the problem, and the run folder is left as it was."""

import json
import os
import zipfile

import numpy as np
import pytest

from lgs_jax import cli, train

from .captures import run_folder, tiny_capture


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A run folder of a tiny capture holding a checkpoint at step 5."""
    tmp = tmp_path_factory.mktemp("saved")
    config = train.FitConfig(data=tiny_capture(tmp / "data"), out=str(tmp / "run"), steps=5,
                             init_points=50)
    run_folder(config, 5)
    return config


def _truncate(out):
    path = os.path.join(out, "checkpoint.npz")
    with open(path, "r+b") as f:
        f.truncate(os.path.getsize(path) // 2)


def _garble(out):  # one member's bytes changed: its CRC no longer matches
    path = os.path.join(out, "checkpoint.npz")
    data = bytearray(open(path, "rb").read())
    at = zipfile.ZipFile(path).getinfo("pool_0.npy").header_offset
    names, extra = int.from_bytes(data[at + 26:at + 28], "little"), int.from_bytes(
        data[at + 28:at + 30], "little")
    start = at + 30 + names + extra + 200  # past the .npy header, in the values
    data[start:start + 8] = bytes(~b & 0xFF for b in data[start:start + 8])
    open(path, "wb").write(bytes(data))


def _meta(out, change):
    path = os.path.join(out, "checkpoint.json")
    meta = json.load(open(path))
    change(meta)
    json.dump(meta, open(path, "w"))


def _arrays(out, change):
    path = os.path.join(out, "checkpoint.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    np.savez(path, **arrays)


CORRUPTIONS = {
    "truncated": (_truncate, "checkpoint.npz: not a readable .npz file"),
    "garbled": (_garble, "checkpoint.npz: not a readable .npz file (Bad CRC-32 for file "
                         "'pool_0.npy')"),
    "not json": (lambda out: open(os.path.join(out, "checkpoint.json"), "w").write("{"),
                 "checkpoint.json: not JSON"),
    "no step": (lambda out: _meta(out, lambda m: m.pop("step")),
                "checkpoint.json: step: expected an int >= 0, got None"),
    "bad pool size": (lambda out: _meta(out, lambda m: m.update(pool_size="x")),
                      "checkpoint.json: pool_size: expected an int >= 1, got 'x'"),
    "no arrays": (lambda out: os.remove(os.path.join(out, "checkpoint.npz")),
                  "checkpoint.npz: missing"),
    "array missing": (lambda out: _arrays(out, lambda a: a.pop("opt_3")),
                      "checkpoint.npz: holds 11 arrays of the opt state, this run's "
                      "configuration has 12 (missing: opt_3)"),
    "array shape": (lambda out: _arrays(out, lambda a: a.update(pool_0=a["pool_0"][:3])),
                    "checkpoint.npz: pool_0 is float32[3, 3], this run's is float32[64, 3]"),
    "other step": (lambda out: _arrays(out, lambda a: a.update(step=np.int64(4))),
                   "checkpoint.npz: of step 4, but checkpoint.json is of step 5"),
}


@pytest.mark.parametrize("name", CORRUPTIONS)
def test_a_corrupted_checkpoint_is_named_and_changes_nothing(saved, tmp_path, capsys, name):
    import shutil

    corrupt, message = CORRUPTIONS[name]
    out = str(tmp_path / "run")
    shutil.copytree(saved.out, out)
    corrupt(out)
    before = {n: open(os.path.join(out, n), "rb").read() for n in sorted(os.listdir(out))}
    code = cli.main(["fit", "--data", saved.data, "--out", out, "--resume", "--steps", "5",
                     "--init-points", "50", "--backend", "reference"])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and "Traceback" not in err, err
    assert f"error: {os.path.join(out, message.split(':')[0])}:{message.split(':', 1)[1]}" \
        in err, err
    assert "start a new run (--overwrite)" in err
    after = {n: open(os.path.join(out, n), "rb").read() for n in sorted(os.listdir(out))}
    assert after == before


def test_a_resume_forgets_the_rows_after_its_checkpoint(tmp_path):
    """metrics.jsonl at a resume from step 5 (five steps done): the rows the resumed run
    writes again go (step 6's, the refinement recorded as 5, which follows the sixth step,
    and the growths of the steps it redoes), those of the first five steps stay."""
    from lgs_jax.train import report, state

    rows = [dict(step=4, loss=1.0), dict(grown_step=5, pair_capacity=64), dict(step=5, loss=0.9),
            dict(refine_step=5, added=1), dict(step=5, heldout_psnr=20.0),
            dict(grown_step=6, pair_capacity=128), dict(step=6, loss=0.8)]
    path = tmp_path / "metrics.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    state._forget_after(str(path), 5)
    assert report.read_metrics(str(path)) == [rows[0], rows[1], rows[2], rows[4]]
