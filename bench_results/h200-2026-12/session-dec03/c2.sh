. scripts/gpu_env.sh
SCENES="guitar_x16_1080p guitar_x64_1080p guitar_x110_4k" SCENE_TIMEOUT=110 bash scripts/scale_gpu_check.sh grad > /dev/null 2>&1
timeout 130 python3 carry/ab2.py --grad --no-gsplat --data carry/data --scenes guitar_x110_4k --rows "localgs#new,localgs#oldat" --repeat 5 2>&1 | grep -v arn > $out/ab_at_x110.log
TEST_TIMEOUT=150 TEST_WORKERS=4 TEST_ARGS="tests/backends/test_gaussian_grads.py tests/backends/test_backward_segments.py" bash scripts/scale_gpu_check.sh tests > /dev/null 2>&1
tail -3 $out/tests.log
grep -h "grad:\|BITWISE\|differ" $out/grad_*.log $out/ab_at_x110.log | cut -c1-220
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
