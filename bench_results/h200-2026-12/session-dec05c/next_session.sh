# Next GPU session (after Dec 5's third session, which had no GPU: BENCHMARKS.md §7 "Dec 5,
# third session"). The calls of session-dec05b/next_session.sh still stand (threaded
# streaming, synthetic 4M's host share, two GPUs). This session adds one measurement, best run
# in the same call as dec05b's call 1 (same machine, after its four skull runs, so that the
# step is compiled once already): the bilateral grid's cost per step (its slice and gradient,
# dense contractions over 8 row blocks, about 3 GFLOP a step at 1063x708) and its held-out
# score on skull, beside dec05b's `--no-stream-images` run:
#   timeout 150 python3 -m lgs_jax fit --data carry/data/skull --steps 3000 \
#     --eval-every 3000 --no-stream-images --bilateral-grid --out /tmp/s_grid \
#     > $out/fit_grid.log 2>&1
#   grep -E '"(ms_per_step|heldout_psnr|compile_seconds)"' $out/fit_grid.log
# Expect its ms per step within ~1.5 ms of the run without the grid; if more, time
# `bilateral_grid.corrected` alone at 1063x708 (jit, 100 calls) and try 4 or 16 row blocks.
