# call 1: the lean forward (mosaic_image_layout, mosaic_block_stops) on the GPU: its tests (slow
# gradient case too) and the lowering tests, then forward time and memory against the planes
# with gsplat in one process per scene
. scripts/gpu_env.sh
TEST_WORKERS=4 TEST_TIMEOUT=200 TEST_ARGS="tests/backends/test_mosaic_staging.py -k 'lean or lowers'" \
  bash scripts/scale_gpu_check.sh tests > $out/tests_summary.txt 2>&1
SCENE_TIMEOUT=95 SCENES="guitar_720p lego_800 guitar_4k guitar_x110_4k" \
  FWD_ROWS=localgs,localgs:image,localgs:lean bash scripts/scale_gpu_check.sh fwd > $out/fwd_summary.txt 2>&1
cat $out/tests_summary.txt; grep -h "e2e\|mem\|MiB" $out/fwd_*.log | head -40
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
