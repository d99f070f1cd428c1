# Call 1: GPU tests of projection and gradients (602cc56, d8be94b never run on a GPU), then
# the A/B at lego x16 against da62541 (memory must be 328 MiB), then issue 18's small scenes.
. scripts/gpu_env.sh
t0=$(date +%s)
TEST_WORKERS=8 TEST_TIMEOUT=260 TEST_ARGS="tests/test_projection.py \
  tests/backends/test_gradients.py tests/backends/test_gaussian_grads.py \
  tests/backends/test_backward_segments.py tests/backends/test_pallas.py tests/train" \
  bash scripts/scale_gpu_check.sh tests > $out/tests.log 2>&1
echo "tests $(( $(date +%s) - t0 )) s" >> $out/times.log
timeout 150 python3 -m benchmarks.ab run lego_x16_1080p --old carry/old --revs da62541 \
  --repeat 5 --data carry/data > $out/ab_legox16.log 2>&1
echo "ab $(( $(date +%s) - t0 )) s" >> $out/times.log
tail -5 $out/tests.log; tail -30 $out/ab_legox16.log; cat $out/times.log
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
