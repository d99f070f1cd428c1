# Next GPU session (issue 17 open; issue 18 closed at 3724a2a), from the repository root; each
# step one `run` call with carry ["carry"] (data: guitar, lego_sh3, skull, lego_train; wheels:
# gsplat 1.5.3, pytest-timeout; old/: `python -m benchmarks.ab prepare 4ebdd1c --to carry/old`).
#
# 1. Nsight Compute of the forward kernels at synthetic 4M, Local-GS and our vanilla (issue
#    17: the Local-GS kernel's lead is 1.58x there and 1.30x at synthetic 10M; which stalls
#    and instruction counts set each kernel's time). This session's attempt segfaulted at
#    ncu's start after two training processes, with gpu_env.sh's exports (LGS_JAX_CACHE,
#    TORCH_EXTENSIONS_DIR, ...) in the environment; the Dec 3 runs that worked had only
#    PYTHONPATH=$PWD and XLA_PYTHON_CLIENT_PREALLOCATE=false. Run it first, in a clean
#    environment, one backend per ncu process:
#      for b in pallas pallas_vanilla; do env -i PATH=$PATH HOME=$HOME PYTHONPATH=$PWD \
#        XLA_PYTHON_CLIENT_PREALLOCATE=false timeout 240 ncu --clock-control none \
#        -k regex:'localgs_kernel|vanilla' -c 1 --set full python3 scripts/ncu_localgs.py \
#        carry/data --scene synthetic4M_1080p --backends $b --kernel mosaic \
#        > $OUT/ncu_fwd_syn4M_$b.txt 2>&1; done
#    then grep "Duration|Registers Per|Achieved Occupancy|Executed Ipc A|Executed Instructions|
#    Stall|No Eligible" in both. What to look for (scripts/strip_occupancy.py, this session):
#    the culling bounds the lead at 2.90x at synthetic 4M (2.76 of 8 strip bits set per pair)
#    and the SASS counts (`kernel_sass.py lego_800 --row localgs / vanilla`: 317 per 8 pairs
#    and warp blending; ~300 per lane before that branch, which if it is the staging is ~9
#    per pair, one lane per pair; the vanilla loop 377 per 8 pairs and warp) predict about
#    that, yet 1.58x is
#    measured: if the Local-GS kernel is not issue-bound (IPC well under the 3.25 of the
#    captures), the stalls say where (long scoreboard at the staging's id -> row loads: a
#    prefetch of the next chunk; barrier: the two-buffer chunk hand-off).
# 2. sh_sums' final form at SH degree 0 on the GPU (compiled for the H200 it has 4ebdd1c's
#    fusions exactly; the first form was 7.45 against 7.31 ms):
#      . scripts/gpu_env.sh; timeout 150 python3 -m benchmarks.ab run synthetic4M_1080p \
#        --old carry/old --revs 4ebdd1c --repeat 7 --data carry/data
# 3. Skull 7k steps at this tree for issue 18's throughput row (12.01 ms per step without
#    compiles on Dec 4, fourth session, before the SH changes; this session the step alone took
#    4.11 ms against da62541's 4.73):
#      TRAIN_SCENES=skull bash scripts/scale_gpu_check.sh train
# 4. Then build per-warp pair lists in the compacted Local-GS forward (BENCHMARKS.md §7 "Dec 4,
#    fifth session": `strip_occupancy.py --chunks` counts 1.76x fewer blend iterations at
#    synthetic 10M, 1.56x at 4M): `mosaic_staging._partition` ballots once per target warp and
#    stores 4 packed index lists, `compact_loop` loops to the busiest warp's count and reads
#    each warp's record by a per-lane shared-memory load (inline Mosaic GPU code), the stop
#    pair a lane vector; same bits (interpret-mode tests against `staged_loop`), then the
#    forward table's Local-GS / vanilla column at the six large scenes.
