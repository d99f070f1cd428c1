# Call 1: the backward's GPU tests (quotient bits first), then the A/Bs against 5831554.
. scripts/gpu_env.sh
t0=$(date +%s)
TEST_WORKERS=8 TEST_TIMEOUT=250 TEST_ARGS="tests/backends/test_mosaic_quotients.py \
  tests/backends/test_backward_segments.py tests/backends/test_gaussian_grads.py \
  tests/backends/test_gradients.py tests/backends/test_mosaic_staging.py \
  tests/backends/test_pallas.py" bash scripts/scale_gpu_check.sh tests > $out/tests_summary.log 2>&1
echo "tests $(( $(date +%s) - t0 )) s" >> $out/times.log
timeout 170 python3 -m benchmarks.ab run synthetic4M_1080p --old carry/old --revs 5831554 \
  --repeat 5 --data carry/data > $out/ab_grad4M.log 2>&1
echo "ab grad $(( $(date +%s) - t0 )) s" >> $out/times.log
left=$(( 575 - ($(date +%s) - t0) ))
timeout $left python3 -m benchmarks.ab run synthetic4M_1080p --fwd --old carry/old \
  --revs 5831554 --repeat 10 --data carry/data > $out/ab_fwd4M.log 2>&1
echo "ab fwd $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/tests_summary.log $out/times.log; grep -v "Warn\|warn" $out/ab_grad4M.log | tail -8
grep -v "Warn\|warn" $out/ab_fwd4M.log | tail -6
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
