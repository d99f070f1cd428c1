"""The Mosaic GPU kernels' machine code for the H200, compiled on a machine without a GPU: each
kernel's registers and, in its main loop, the SASS instructions per iteration by opcode.

    build/gpu-offline/bin/python scripts/kernel_sass.py SCENE [--grad] [--row localgs]
        [--kernel backward] [--tuning NAME=VALUE ...] [--data DIR] [--keep DIR]

`scripts/gpu_memory_offline.py` compiles the scene's program for the H200 (deviceless); Mosaic
GPU compiles its kernels to PTX on the way and, with MOSAIC_GPU_DUMP_PTX / _PTXAS /
MOSAIC_GPU_DUMP_TO set, writes them out. Here each PTX goes through the CUDA wheel's ptxas
(sm_90a) and `cuobjdump -sass` (the package's `sass` extra: `build/gpu-offline/bin/pip install
".[gpu,sass]"`), then the loops are found by their backward branches. For a
kernel whose time is its instruction count (the backward kernel at synthetic 4M: 81% of the
issue slots busy) the count per iteration of the pair
loop is what a change buys, before any GPU runs it. Printed per loop: its instructions and, from
the loop's first forward branch on (the per-pair step past a chunk's staging, in the backward
kernel), the instructions of that part.
"""

from __future__ import annotations

import argparse
import collections
import glob
import os
import re
import site
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INSTRUCTION = re.compile(r"\s*/\*([0-9a-f]{4,})\*/\s+(.*?);")


def tool(name: str) -> str:
    """A CUDA tool from this environment's nvidia wheels (ptxas from the CUDA plugin's)."""
    found = [path for d in site.getsitepackages()
             for path in glob.glob(os.path.join(d, "nvidia", "cu*", "bin", name))]
    if not found:
        raise SystemExit(f"{name}: not in this environment's nvidia wheels (pip install "
                         f"nvidia-cuda-{'nvcc' if name == 'ptxas' else name})")
    return found[0]


def instructions(sass: str) -> list[tuple[int, str]]:
    """(address, instruction) of a `cuobjdump -sass` listing, predicates kept."""
    return [(int(m.group(1), 16), m.group(2).strip())
            for m in map(INSTRUCTION.match, sass.splitlines()) if m]


def opcode_mix(body: list[str]) -> str:
    """'FMUL 44, FSEL 41, ...': the opcodes (without predicate and modifiers) by count."""
    ops = collections.Counter(re.sub(r"^@!?U?P\w+\s+", "", t).split()[0].split(".")[0]
                              for t in body)
    return ", ".join(f"{k} {v}" for k, v in ops.most_common())


def loops(ins: list[tuple[int, str]]) -> list[tuple[int, int]]:
    """(first, last) addresses of each loop: a branch to an address at or before its own."""
    out = []
    for a, t in ins:
        target = re.search(r"BRA\s.*?0x([0-9a-f]+)", t)
        if target and int(target.group(1), 16) <= a:
            out.append((int(target.group(1), 16), a))
    return out


def report(name: str, ptxas_log: str, sass: str) -> None:
    registers = re.search(r"Used (\d+) registers", ptxas_log)
    ins = instructions(sass)
    print(f"== {name}: {registers.group(1) if registers else '?'} registers, {len(ins)} "
          "instructions")
    for lo, hi in loops(ins):
        body = [(a, t) for a, t in ins if lo <= a <= hi]
        print(f"  loop {lo:#x}-{hi:#x}: {len(body)} instructions: "
              f"{opcode_mix([t for _, t in body])}")
        skip = [int(m.group(1), 16) for _, t in body
                for m in [re.search(r"BRA\s.*?0x([0-9a-f]+)", t)] if m and int(m.group(1), 16) > lo]
        if skip and skip[0] < hi:
            tail = [t for a, t in body if a >= skip[0]]
            print(f"    from {skip[0]:#x} (past the first forward branch): {len(tail)} "
                  f"instructions: {opcode_mix(tail)}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--grad", action="store_true")
    ap.add_argument("--row", default="localgs", help="a benchmarks.scale.ROWS key")
    ap.add_argument("--kernel", default="", help="only kernels whose name contains this")
    ap.add_argument("--tuning", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--data", default=os.path.join(ROOT, "..", "shared", "data"))
    ap.add_argument("--keep", help="write the PTX, ptxas logs and SASS here (else a temp dir)")
    args = ap.parse_args(argv)
    out = args.keep or tempfile.mkdtemp(prefix="kernel_sass_")
    os.makedirs(out, exist_ok=True)
    env = dict(os.environ, MOSAIC_GPU_DUMP_PTX="1", MOSAIC_GPU_DUMP_PTXAS="1",
               MOSAIC_GPU_DUMP_TO=out)
    cmd = [sys.executable, os.path.join(ROOT, "scripts", "gpu_memory_offline.py"), args.scene,
           "--data", args.data, "--row", args.row] + (["--grad"] if args.grad else [])
    for t in args.tuning:
        cmd += ["--tuning", t]
    compiled = subprocess.run(cmd, env=env, capture_output=True, text=True)
    failed = [line for line in compiled.stderr.splitlines() if "error:" in line]
    if compiled.returncode or failed:  # a kernel the GPU compiler rejects writes no PTX
        sys.exit("\n".join(failed[:8]) or compiled.stdout[-2000:] + compiled.stderr[-2000:])
    ptxas, cuobjdump = tool("ptxas"), tool("cuobjdump")
    tools = dict(os.environ, PATH=os.path.dirname(tool("nvdisasm")) + os.pathsep
                 + os.environ.get("PATH", ""))  # cuobjdump -sass runs nvdisasm
    for ptx in sorted(glob.glob(os.path.join(out, "*.ptx"))):
        name = os.path.basename(ptx)[:-4]
        if args.kernel not in name:
            continue
        cubin = ptx[:-4] + ".cubin"
        log = subprocess.run([ptxas, "-v", "-arch=sm_90a", ptx, "-o", cubin],
                             capture_output=True, text=True, check=True).stderr
        sass = subprocess.run([cuobjdump, "-sass", cubin], capture_output=True, text=True,
                              check=True, env=tools).stdout
        with open(ptx[:-4] + ".sass", "w") as f:
            f.write(sass)
        report(name, log, sass)
    return 0


if __name__ == "__main__":
    sys.exit(main())
