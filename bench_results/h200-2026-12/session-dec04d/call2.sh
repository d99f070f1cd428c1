# Call 2: forward + backward against gsplat with the 10-column table, walked rows
# (compiled offline for the H200: 597 MiB at 4M, 1561 at 10M).
. scripts/gpu_env.sh
t0=$(date +%s)
SCENES="synthetic4M_1080p synthetic10M_4k guitar_x110_4k" GRAD_ROWS=localgs@walked \
  SCENE_TIMEOUT=200 bash scripts/scale_gpu_check.sh grad > $out/grad.log 2>&1
echo "grad $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/times.log $out/grad.log
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
