# One call for a session that may get only one machine start (Dec 5, sixth session): issue 17's
# host-time probe, the colour features' and appearance embeddings' GPU tests, the features' cost
# per pass, skull with appearance embeddings (against the fifth session's plain 3000-step run).
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
timeout 100 python3 scripts/donate_probe.py --data carry/data --scenes guitar_x110_4k \
  synthetic4M_1080p --repeat 20 > $out/donate.log 2>&1
echo "donate rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; grep -v "arn" $out/donate.log
timeout 80 python3 -m pytest -q -p no:cacheprovider -n 8 tests/test_colors.py \
  tests/train/test_appearance.py > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; tail -n 4 $out/tests.log
timeout 60 python3 -m benchmarks.features --data carry/data --scene guitar_x16_1080p \
  --channels 8,32 --repeat 5 > $out/features.log 2>&1
echo "features rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; cat $out/features.log
for opt in "" "--app-opt"; do
  timeout 110 python3 -m lgs_jax fit --data carry/data/skull --steps 3000 --eval-every 3000 \
    $opt --out /tmp/s$opt > $out/fit$opt.log 2>&1
  echo "fit $opt rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
  grep -E '"(ms_per_step|heldout_psnr|heldout_ssim|gaussians|compile_seconds)"' \
    /tmp/s$opt/result.json >> $out/times.log
done
cat $out/device.txt $out/times.log
