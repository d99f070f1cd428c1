# Next GPU session (after Dec 5's fourth session, whose budget went into one call on an H100
# and failed machine starts: BENCHMARKS.md §7 "Dec 5, fourth session"). From the repository
# root, each call one `run`; carry only what it reads (carry/ whole is over 64 MiB).
#
# Call 1 (about 5 min; carry carry/data/skull, carry/data/guitar, carry/wheels): issue 17's two
# open rows with the new queued column (blocked and queued e2e against gsplat, 20 rounds), then
# skull without streaming (the baseline the fourth session's streamed and grid runs lack; give
# the run 170 s if it is the first of the machine: cold compiles):
#   bash bench_results/h200-2026-12/session-dec05d/call2.sh
# If the budget allows, the same for the other seven scenes of issue 17's table (call6.sh of
# session-dec05b with `--rows localgs,vanilla`), so that the queued column covers the table.
#
# Call 2 (about 4 min): synthetic 4M's host share after the buckets default
# (session-dec05b/next_session.sh, call 2), and the camera-gradient fix's GPU check:
#   . scripts/gpu_env.sh; timeout 200 python3 scripts/kernel_times.py --data carry/data \
#     --scenes synthetic4M_1080p --rows localgs --iters 5 --top 30 --no-gsplat --host 40 \
#     > $out/kt_syn4M.log 2>&1; tail -n 40 $out/kt_syn4M.log
#   timeout 200 python3 -m pytest -q -p no:cacheprovider -n 8 tests/backends/test_gradients.py \
#     tests/train/test_camera_opt.py > $out/tests.log 2>&1; tail -n 5 $out/tests.log
#
# Call 3, on kind "nvidia-h200-x2" where lent: fit --devices 1 vs 2 (session-dec05b call 3).
