# call 1: the GPU tests of the three unrun kernel changes (ff6056a reduction, dad7a98 exp2,
# 2f92278 miss as α = 0), then in-process A/B (benchmarks.ab) against b2c9b27, ff6056a, dad7a98
# (carry/old from `python -m benchmarks.ab prepare b2c9b27 ff6056a dad7a98 --to carry/old`)
. scripts/gpu_env.sh
TEST_WORKERS=8 TEST_TIMEOUT=240 TEST_ARGS="tests/backends/test_backward_segments.py tests/backends/test_gaussian_grads.py tests/backends/test_gradients.py tests/backends/test_mosaic_staging.py tests/backends/test_pallas.py" bash scripts/scale_gpu_check.sh tests > $out/tests_summary.txt 2>&1
timeout 200 python3 -m benchmarks.ab run synthetic4M_1080p --old carry/old --data carry/data --repeat 5 --against ff6056a 2>&1 | grep -v Warn > $out/ab_synthetic4M_1080p.log
timeout $((570 - SECONDS)) python3 -m benchmarks.ab run guitar_x64_1080p --old carry/old --data carry/data --repeat 5 2>&1 | grep -v Warn > $out/ab_guitar_x64_1080p.log
cat $out/tests_summary.txt; tail -8 $out/ab*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
