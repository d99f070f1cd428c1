# call 4: forward + backward against gsplat on the synthetic scenes and the small ones
. scripts/gpu_env.sh
SCENES="synthetic4M_1080p synthetic10M_4k lego_800 guitar_720p guitar_4k" SCENE_TIMEOUT=130 \
  bash scripts/scale_gpu_check.sh grad > $out/grad_summary.txt 2>&1
cat $out/grad_summary.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
