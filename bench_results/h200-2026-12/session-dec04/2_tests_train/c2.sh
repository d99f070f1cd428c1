# call 2: the backward's GPU tests with rows without ∂L/∂z for image losses (kernel_steps.row_width),
# then skull training, 7k steps (exp2 in the forward and backward: a NaN would be α's bits differing)
. scripts/gpu_env.sh
base=$out
TEST_WORKERS=8 TEST_TIMEOUT=250 TEST_ARGS="tests/backends/test_backward_segments.py tests/backends/test_gaussian_grads.py tests/backends/test_gradients.py tests/backends/test_mosaic_staging.py" bash scripts/scale_gpu_check.sh tests > $base/tests_summary.txt 2>&1
echo "tests done at $SECONDS s" >> $base/progress.log
OUT=$base/skull TRAIN_SCENES=skull TRAIN_TIMEOUT=$((575 - SECONDS)) bash scripts/scale_gpu_check.sh train > $base/train_skull.txt 2>&1
echo "skull done at $SECONDS s" >> $base/progress.log
cat $base/progress.log $base/tests_summary.txt; tail -n 6 $base/train_skull.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
