# call 2: call 1's tests stopped at 240 s with 69 of 72 done (no failure printed): again, each
# test named (-v) and cut at 200 s with its stack (pytest-timeout carried), then the kernels'
# device time at synthetic 4M forward + backward (no gsplat) and the forward's unroll 8 vs 4
. scripts/gpu_env.sh
TEST_WORKERS=8 TEST_TIMEOUT=330 TEST_ARGS="-v --timeout 200 tests/backends/test_backward_segments.py tests/backends/test_gaussian_grads.py tests/backends/test_gradients.py tests/backends/test_mosaic_staging.py" bash scripts/scale_gpu_check.sh tests > $out/tests_summary.txt 2>&1
timeout $((470 - SECONDS)) python3 scripts/kernel_times.py --data carry/data --scenes synthetic4M_1080p --grad --rows localgs --iters 5 --top 8 --no-gsplat 2>&1 | grep -v "Warn\|warn(" > $out/kt_syn4M.log
for s in guitar_x64_1080p guitar_x110_4k; do
  timeout $((575 - SECONDS)) python3 -m benchmarks.scale --no-gsplat --data carry/data --scenes $s \
    --rows localgs,localgs:unroll4 --repeat 10 2>&1 | grep -v "Warn\|warn(" > $out/unroll_$s.log; done
cat $out/tests_summary.txt; grep -n "Timeout\|FAILED\|Error" $out/tests.log | head; tail -4 $out/tests.log
grep "==\|busy\|backward" $out/kt_syn4M.log | head -12; grep -h " e2e \|raster" $out/unroll_*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
