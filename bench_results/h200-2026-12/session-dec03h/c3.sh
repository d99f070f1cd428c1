# call 3: the 3-4 GPU tests that never finish (calls 1, 2: 69 of 73 done, pytest-timeout's signal
# never fired, so they wait in C: a kernel that hangs, or a compile): each test named (-vv, as -q
# cancels one -v), cut at 150 s by the thread method (all stacks dumped, the worker replaced)
. scripts/gpu_env.sh
TEST_WORKERS=8 TEST_TIMEOUT=330 TEST_ARGS="-vv --timeout 150 --timeout-method thread --durations 12 tests/backends/test_backward_segments.py tests/backends/test_gaussian_grads.py tests/backends/test_gradients.py tests/backends/test_mosaic_staging.py" bash scripts/scale_gpu_check.sh tests > $out/tests_summary.txt 2>&1
nvidia-smi --query-gpu=utilization.gpu --format=csv > $out/smi.txt 2>&1
grep -n "Timeout\|crashed\|FAILED\|rror" $out/tests.log | head -20; grep -c PASSED $out/tests.log; tail -20 $out/tests.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
