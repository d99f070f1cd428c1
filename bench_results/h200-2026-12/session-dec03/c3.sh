. scripts/gpu_env.sh
for s in guitar_x110_4k guitar_x16_1080p; do
timeout 150 python3 -m benchmarks.scale --grad --no-gsplat --data carry/data --scenes $s --rows "localgs,localgs@walked,localgs@split" --repeat 5 2>&1 | grep -v arn > $out/grad_split_$s.log
done
for s in guitar_x110_4k guitar_x16_1080p; do timeout 60 python3 carry/dispatch.py $s 2>&1 | grep -v arn >> $out/dispatch.log; done
TEST_TIMEOUT=200 TEST_WORKERS=4 TEST_ARGS="tests/backends/test_gaussian_grads.py tests/backends/test_backward_segments.py tests/backends/test_gradients.py" bash scripts/scale_gpu_check.sh tests > /dev/null 2>&1
tail -3 $out/tests.log
cat $out/dispatch.log
grep -h "grad:\|BITWISE\|differ\|overflow" $out/grad_split_*.log | cut -c1-220
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
