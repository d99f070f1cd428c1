# Next GPU session (after Dec 5's fifth session: one call ran, BENCHMARKS.md §7 "Dec 5, fifth
# session"). From the repository root, each call one `run`; carry only what it reads
# (carry/data/guitar and carry/wheels; carry/data/skull for the skull run).
#
# Call 1 (about 4 min): issue 17's last item. The host-time probe (is the blocked call's
# 0.74 ms at guitar x110 4K XLA re-recording command buffers?) and the features' cost per pass:
#   bash bench_results/h200-2026-12/session-dec05e/call_four.sh
# then (same call if time allows) the colours' tests at the vmap test's new tolerance:
#   timeout 90 python3 -m pytest -q -p no:cacheprovider -n 8 tests/test_colors.py
#
# Call 2: skull without streaming beside the fourth session's streamed runs, synthetic 4M's
# host share (session-dec05d/next_session.sh, calls 1 (its last run) and 2).
#
# Call 3, on kind "nvidia-h200-x2" where lent: fit --devices 1 vs 2 (session-dec05b call 3).
