"""The kernels XLA compiles the projection into on this device (fusions, sorts, gathers, custom
calls of the entry computation, one line each): how many passes `lgs_jax.projection.project`
makes over the Gaussians and which inputs each reads (BENCHMARKS.md §7, Dec 1).

    python scripts/projection_hlo.py [--data DIR] [--scene guitar_x16_1080p]
"""

from __future__ import annotations

import argparse
import os
import re
import sys

import jax

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from benchmarks.common import add_data_argument, load_scene  # noqa: E402
from lgs_jax.projection import project  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_argument(ap)
    ap.add_argument("--scene", default="guitar_x16_1080p")
    args = ap.parse_args()
    g, cam = load_scene(args.scene, args.data)
    g, cam = jax.device_put(g), jax.device_put(cam)
    text = jax.jit(project).lower(g, cam).compile().as_text()
    for line in text[text.index("ENTRY"):].splitlines():
        if re.search(r"= .*(fusion|custom-call|sort|scatter|gather|reduce)\(", line):
            print(line.strip()[:260])
    return 0


if __name__ == "__main__":
    sys.exit(main())
