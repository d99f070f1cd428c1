# call 5: forward + backward against gsplat (issue 18's table), default and walked rows
. scripts/gpu_env.sh
SCENES="guitar_x16_1080p guitar_x64_1080p guitar_x110_4k" SCENE_TIMEOUT=110 bash scripts/scale_gpu_check.sh grad > $out/grad.txt 2>&1
tail -12 $out/grad.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
