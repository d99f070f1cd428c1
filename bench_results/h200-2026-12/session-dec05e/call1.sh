# Call 1: issue 17's two missed scenes (blocked and queued e2e against gsplat in the process),
# then skull's no-stream baseline for the fourth session's streaming and grid runs.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
for spec in synthetic4M_1080p:150 guitar_x110_4k:90; do
  s=${spec%%:*}; t=${spec##*:}
  timeout $t python3 -m benchmarks.scale --data carry/data --scenes $s \
    --rows localgs,vanilla --repeat 20 --big-repeat 20 --csv $out/fwd_$s.csv > $out/fwd_$s.log 2>&1
  echo "fwd $s rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
  cat $out/times.log; grep -v "arn\|lambda\|^device" $out/fwd_$s.log | tail -n 3 | cut -c1-300
done
timeout 150 python3 -m lgs_jax fit --data carry/data/skull --steps 3000 --eval-every 3000 \
  --no-stream-images --out /tmp/s_ns > $out/fit_nostreamimages.log 2>&1
echo "fit no-stream rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
grep -E '"(ms_per_step|heldout_psnr|compile_seconds)"' $out/fit_nostreamimages.log >> $out/times.log
cat $out/device.txt $out/times.log
