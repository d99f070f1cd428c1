# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call.
# 0. This session's two unmeasured changes (the projection's columns behind the barrier,
#    19a8f91; gaussian_grads writing two columns into the layout's first/count buffers,
#    cb983cd) against the session's start, in one process (ab_pkg.py: copy it to carry/, and
#    carry/old/lgs_old = `git archive 4a3f59a lgs_jax` renamed, as built on Dec 3):
#      for s in guitar_x16_1080p guitar_x64_1080p guitar_x110_4k; do
#        timeout 150 python3 carry/ab_pkg.py $s 7; done
#    Expected: the same bits; x110 walked rows about 1591 against 1667 MiB; a few tenths of a
#    ms less at x110 (three concatenates gone from the forward, the cotangents' from the
#    backward). Revert whichever is slower.
# 1. The projection's columns behind the barrier (landed on Dec 3, third session, unmeasured on a
#    GPU): forward and forward + backward against gsplat, and the 4K forward's kernels, where the
#    four input_concatenate fusions (0.26 ms) should be gone:
#      SCENES="guitar_720p guitar_x16_1080p guitar_x64_1080p guitar_x110_4k" FWD_ROWS=localgs \
#        SCENE_TIMEOUT=100 bash scripts/scale_gpu_check.sh fwd
#      SCENES="guitar_x16_1080p guitar_x64_1080p guitar_x110_4k" SCENE_TIMEOUT=110 \
#        bash scripts/scale_gpu_check.sh grad
#      python3 scripts/kernel_times.py --data carry/data --scenes guitar_x110_4k --rows localgs \
#        --iters 5 --top 40 --no-gsplat
# 2. Whole-tile backward blocks at 1080p (issue 18's memory: the x16 walked peak holds two
#    half-tile rows per pair, 96 MiB; whole tiles would make it 48, about 278 MiB = 0.98x gsplat's):
#      python3 -m benchmarks.scale --grad --no-gsplat --data carry/data --scenes S \
#        --rows localgs@walked,localgs:bwd256@walked,localgs:px256@walked,localgs,localgs:px256 \
#        --repeat 7      # S = guitar_x16_1080p, then guitar_x64_1080p
#    If whole tiles cost no time now (they cost 10-23% on Dec 1, before the split backward and
#    the compacted forward), lower KernelConfig.mosaic_whole_tile_from to 8160 or below.
# 3. The identity-derivative barrier alone (identity_barrier_only.patch, now on top of the
#    columns change it would need rebasing) is not needed if step 1 shows no copies at the
#    backward's remat barrier.
