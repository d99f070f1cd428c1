# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call.
# Set up carry/ as on Dec 3 (data, gsplat wheel), plus:
#   carry/ab_pkg.py = this folder's ab_pkg.py; carry/old/lgs_old = `git archive cdc3380 lgs_jax`
#   renamed lgs_old (cdc3380: before `backward_segments.entries`, the split backward's
#   entering carries computed after the forward).
# 0. The backward kernel's inputs changed (five entry buffers instead of nine): its GPU tests,
#    then the A/B in one process (time, memory, same bits), forward + backward:
#      TEST_WORKERS=8 bash scripts/scale_gpu_check.sh tests
#      for s in guitar_4k guitar_720p guitar_x16_1080p guitar_x64_1080p guitar_x110_4k; do
#        timeout 120 python3 carry/ab_pkg.py $s 7; done
#    Expected (scripts/gpu_memory_offline.py, MiB): guitar_4k 408 -> 282 (measured: 282),
#    720p 64 -> 50, x16 walked 278 -> 248, x64 walked 841 -> 841, x110 walked 1578 -> 1546.
#    Time: at guitar_4k walked rows took ~0.2 ms more in two 5-round runs (8_entries/); find
#    where with every kernel's time, this tree and a copy with the old package (as c23.sh):
#      python3 scripts/kernel_times.py --grad --data carry/data --scenes guitar_4k \
#        --rows localgs --iters 10 --top 40 --no-gsplat   (kernel_times has no @walked rows)
# 1. The small scenes against gsplat (not measured since Dec 2):
#      SCENES="lego_800 guitar_720p guitar_4k" GRAD_ROWS=localgs,localgs@walked \
#        bash scripts/scale_gpu_check.sh grad
# 2. Training unchanged? TRAIN_SCENES=lego bash scripts/scale_gpu_check.sh train
# 3. The 4K forward's host share (issue 17's 0.8x): session-dec03d/cb_probe.py with more variants,
#    e.g. {"xla_gpu_graph_min_graph_size": 1} (since the table before binning, the Local-GS
#    kernel runs outside XLA's command buffers: `mpmd_map.0` rather than `command_buffer_46` in
#    3_which/kt_*.log) and the command buffer types with custom calls listed explicitly;
#    `python3 cb_probe.py guitar_x110_4k 20`.
# 4. Issue 17 asks that a full run of the benchmark finish within 10 minutes on the GPU; not
#    timed since the scenes and rows grew (9 scenes x 3 rows + gsplat, 20 rounds, 7 from 5M):
#      . scripts/gpu_env.sh; export LGS_JAX_CACHE=$PWD/build/jax_cache
#      time timeout 590 python3 -m benchmarks.scale --data carry/data --csv $OUT/full.csv
#    (lines come per scene, so a cut run still says how far it got); if it does not fit, cut
#    the per-scene compile count (the stage programs) or the default rounds, not the scenes.
