# Call 1: the 10-column table (6848b3a) on the GPU: the staging/mask/gradient tests, then
# A/Bs against 786c63c (the tree before it): bits must be equal, memory lower.
. scripts/gpu_env.sh
t0=$(date +%s)
TEST_WORKERS=8 TEST_TIMEOUT=260 TEST_ARGS="tests/test_pairs.py \
  tests/backends/test_mosaic_staging.py tests/backends/test_table_kernel.py \
  tests/backends/test_pallas.py tests/backends/test_backward_segments.py \
  tests/backends/test_gradients.py" bash scripts/scale_gpu_check.sh tests > $out/tests_summary.log 2>&1
echo "tests $(( $(date +%s) - t0 )) s" >> $out/times.log
timeout 150 python3 -m benchmarks.ab run synthetic4M_1080p --old carry/old --revs 786c63c \
  --repeat 5 --data carry/data > $out/ab_grad4M.log 2>&1
echo "ab grad $(( $(date +%s) - t0 )) s" >> $out/times.log
left=$(( 575 - ($(date +%s) - t0) ))
timeout $left python3 -m benchmarks.ab run synthetic10M_4k --fwd --old carry/old --revs 786c63c \
  --repeat 5 --data carry/data > $out/ab_fwd10M.log 2>&1
echo "ab fwd $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/tests_summary.log $out/times.log; grep -v "Warn\|warn" $out/ab_grad4M.log | tail -8
grep -v "Warn\|warn" $out/ab_fwd10M.log | tail -6
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
