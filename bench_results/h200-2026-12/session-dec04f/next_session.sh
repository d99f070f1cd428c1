# Next GPU session (issue 17 open: synthetic 10M at 0.80-0.83x gsplat end to end and the
# Local-GS lead 1.48-1.50x there; everything else met, BENCHMARKS.md §7 "Dec 4, sixth
# session"), from the repository root; each step one `run` call with carry ["carry"].
#
# 1. (Modelled on a CPU this session, not worth building: whole-tile blocks of one
#    warpgroup, two pixels per lane, walking per-warp lists of two strips each, stage each
#    chunk once per tile instead of twice, but their loop iterations (strip_occupancy.py
#    --chunks with `whole` forced: synthetic 10M 1,721,795 against 2,863,133 half-tile
#    iterations) each blend two pixels per lane, about 570 instead of 331 instructions per 8
#    pairs: 2.5% fewer instructions in all at synthetic 10M, less than run-to-run noise, and
#    without the half tiles' independent early exits. BENCHMARKS.md §7, Dec 4, sixth session.)
# 2. The forward's host share at synthetic 10M (about 0.45 ms per blocked call: XLA re-records
#    its command buffers every call, and the CUB sorts' host side): kernel_times.py --host 40
#      . scripts/gpu_env.sh; timeout 200 python3 scripts/kernel_times.py --data carry/data \
#        --scenes synthetic10M_4k --host 40 > $OUT/kt_syn10M.log 2>&1
# 3. The issue table once more, 20 rounds, where the ratio is closest to its target:
#      for s in synthetic10M_4k guitar_x110_4k; do timeout 100 python3 -m benchmarks.scale \
#        --data carry/data --scenes $s --rows localgs,vanilla --repeat 20 \
#        > $OUT/fwd_$s.log 2>&1; done
# 4. Skull 7k steps with per-warp lists in the training step (the gradient's forward uses
#    them): TRAIN_SCENES=skull bash scripts/scale_gpu_check.sh train
