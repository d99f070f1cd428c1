"""This tree's package against earlier revisions of it, in one process: the time, memory and bits
of a change, measured as a ratio in one run (alternating rounds), where two sessions' absolute
times would differ by more than the change.

    python -m benchmarks.ab prepare REV [REV ...] [--to carry/old]     # here, with git
    XLA_PYTHON_CLIENT_PREALLOCATE=false python -m benchmarks.ab run SCENE [--old carry/old]
        [--revs REV,REV] [--against REV] [--repeat 7] [--fwd] [--data carry/data]  # on the GPU

`prepare` writes each revision's `lgs_jax` as the package `lgs_<rev>` (`git archive`, every
`lgs_jax` in its files renamed) under `--to`, a git-ignored folder the device call carries.
`run` renders SCENE (a `benchmarks.common.SCENES` name, or e.g. synthetic:300@32x32) with every
package, the `pallas` backend's defaults at the scene's pair capacity: with --fwd the image, else
the value and gradient of Σ image·w (w fixed, random) over every field, both with the default
row buffer and with rows for the walked pairs (`row_capacity`, "@walked"). Printed per row: the
median ms, XLA's compiled memory (temporaries + outputs) and whether every output equals the
current tree's to the bit (or, with --against REV, that revision's: the bits of a change that
is not the newest).
"""

from __future__ import annotations

import argparse
import importlib
import io
import os
import re
import subprocess
import sys
import tarfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def package_name(rev: str) -> str:
    """The module name revision `rev`'s package gets: lgs_<rev> (rev's word characters)."""
    return "lgs_" + re.sub(r"\W", "_", rev)


def prepare(revs, to: str) -> None:
    """Write lgs_jax at each revision as package `package_name(rev)` under `to`."""
    for rev in revs:
        name = package_name(rev)
        archive = subprocess.run(["git", "-C", ROOT, "archive", rev, "lgs_jax"],
                                 capture_output=True, check=True).stdout
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            for member in tar.getmembers():
                if not member.isfile():
                    continue
                path = os.path.join(to, name + member.name[len("lgs_jax"):])
                os.makedirs(os.path.dirname(path), exist_ok=True)
                data = tar.extractfile(member).read()
                if member.name.endswith(".py"):
                    data = data.replace(b"lgs_jax", name.encode())
                with open(path, "wb") as f:
                    f.write(data)
        print(f"{rev}: {os.path.join(to, name)}")


def run(args) -> None:
    """The A/B of `run` (module docstring)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    sys.path[:0] = [ROOT, args.old]
    import lgs_jax
    from benchmarks import scale
    from benchmarks.common import compiled_mib, device_line, median_ms, parse_scene

    revs = [r for r in args.revs.split(",") if r] if args.revs else sorted(
        d[len("lgs_"):] for d in os.listdir(args.old) if d.startswith("lgs_"))
    packages = [lgs_jax] + [importlib.import_module(package_name(r)) for r in revs]
    against = package_name(args.against) if args.against else "lgs_jax"
    if against not in [p.__name__ for p in packages]:
        raise SystemExit(f"--against {args.against}: not among the revisions {revs}")
    case = parse_scene(args.scene, args.data)
    g, cam = jax.device_put(case.scene), jax.device_put(case.camera)
    cap = lgs_jax.pair_capacity(scale.count_pairs(g, cam))
    w = jax.random.normal(jax.random.key(0), (cam.height, cam.width, 3), jnp.float32)
    walked = int(lgs_jax.render(g, cam, backend="pallas",
                                capacity=cap).stats.backend_stats.pairs_walked)
    fns, mem, out = {}, {}, {}
    for pkg in packages:
        gp = pkg.Gaussians(**{k: getattr(g, k) for k in g.__dataclass_fields__})
        cp = pkg.Camera(**{k: getattr(cam, k) for k in cam.__dataclass_fields__})
        for rows in (None,) if args.fwd else (None, lgs_jax.pair_capacity(walked)):
            name = pkg.__name__ + ("@walked" if rows else "")

            def loss(gp, w, pkg=pkg, cp=cp, rows=rows):
                return jnp.sum(pkg.render(gp, cp, backend="pallas", capacity=cap,
                                          row_capacity=rows).image * w)

            f = jax.jit(loss if args.fwd else jax.value_and_grad(loss))
            out[name] = [np.asarray(x) for x in jax.tree.leaves(f(gp, w))]
            mem[name] = compiled_mib(f, gp, w)
            fns[name] = lambda f=f, gp=gp: jax.block_until_ready(f(gp, w))
    ms = median_ms(fns, args.repeat)
    print(device_line())
    for name in fns:
        ref = out[re.sub(r"^lgs_\w+?(@walked)?$", against + r"\1", name)]
        same = all(np.array_equal(a, b) for a, b in zip(out[name], ref))
        print(f"{args.scene:>18} {name:<22} {'fwd' if args.fwd else 'fwd+bwd'} "
              f"{ms[name]:8.2f} ms  mem {mem[name]:7.0f} MiB  same bits as {against}: {same}",
              flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("prepare", help="write earlier revisions' packages (needs git)")
    p.add_argument("revs", nargs="+")
    p.add_argument("--to", default=os.path.join(ROOT, "carry", "old"))
    r = sub.add_parser("run", help="the A/B on this machine's default device")
    r.add_argument("scene")
    r.add_argument("--old", default=os.path.join(ROOT, "carry", "old"))
    r.add_argument("--revs", help="comma-separated revisions (default: every one under --old)")
    r.add_argument("--against", help="compare bits with this revision (default: this tree)")
    r.add_argument("--repeat", type=int, default=7)
    r.add_argument("--fwd", action="store_true", help="the image alone (else the gradient)")
    r.add_argument("--data", default=os.path.join(ROOT, "carry", "data"))
    args = ap.parse_args(argv)
    if args.command == "prepare":
        prepare(args.revs, args.to)
    else:
        run(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
