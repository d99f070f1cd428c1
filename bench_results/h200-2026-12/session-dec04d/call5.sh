# Call 5: forward + backward against gsplat at the densified captures, walked rows, this tree
# (issue 18's table; lego x16 never measured before).
. scripts/gpu_env.sh
t0=$(date +%s)
SCENES="guitar_x16_1080p lego_x16_1080p guitar_x64_1080p" GRAD_ROWS=localgs@walked \
  SCENE_TIMEOUT=100 bash scripts/scale_gpu_check.sh grad > $out/grad.log 2>&1
echo "grad $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/times.log $out/grad.log
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
