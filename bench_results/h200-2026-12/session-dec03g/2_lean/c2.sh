# call 2: the lean forward's tests (call 1 ran none: the quoted -k), its kernels' device time at
# 720p against the planes, the 720p forward again with 40 rounds, then forward + backward with
# gsplat at 4K and x16
. scripts/gpu_env.sh
T=tests/backends/test_mosaic_staging.py
TEST_WORKERS=4 TEST_TIMEOUT=200 TEST_ARGS="$T::test_lean_forward_renders_the_planes_images \
$T::test_lean_forward_gives_the_planes_gradients $T::test_lean_forward_applies_where_its_conditions_hold \
$T::test_in_kernel_staging_lowers_for_the_gpu" bash scripts/scale_gpu_check.sh tests > $out/tests_summary.txt 2>&1
timeout 80 python3 scripts/kernel_times.py --data carry/data --scenes guitar_720p \
  --rows localgs,localgs:lean --iters 20 --top 12 --no-gsplat > $out/kt_720p.log 2>&1
timeout 60 python3 -m benchmarks.scale --no-gsplat --data carry/data --scenes guitar_720p \
  --rows localgs,localgs:image,localgs:lean --repeat 40 > $out/fwd40_720p.log 2>&1
SCENE_TIMEOUT=110 SCENES="guitar_4k guitar_x16_1080p" GRAD_ROWS=localgs@walked,localgs:lean@walked \
  bash scripts/scale_gpu_check.sh grad > $out/grad_summary.txt 2>&1
cat $out/tests_summary.txt; grep -i "busy\|==" $out/kt_720p.log | head; grep e2e $out/fwd40_720p.log
grep -h "grad:" $out/grad_*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
