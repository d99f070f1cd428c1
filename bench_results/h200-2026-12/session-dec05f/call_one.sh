# One call for a session that may get only one machine start (Dec 5, sixth session): issue 17's
# host-time probe, the colour features' GPU tests and cost per pass, skull without streaming.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
timeout 110 python3 scripts/donate_probe.py --data carry/data --scenes guitar_x110_4k \
  synthetic4M_1080p --repeat 20 > $out/donate.log 2>&1
echo "donate rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; grep -v "arn" $out/donate.log
timeout 90 python3 -m pytest -q -p no:cacheprovider -n 8 tests/test_colors.py > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; tail -n 4 $out/tests.log
timeout 80 python3 -m benchmarks.features --data carry/data --scene guitar_x16_1080p \
  --channels 8,32 --repeat 5 > $out/features.log 2>&1
echo "features rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; cat $out/features.log
timeout 150 python3 -m lgs_jax fit --data carry/data/skull --steps 3000 --eval-every 3000 \
  --no-stream-images --out /tmp/s_ns > $out/fit_nostreamimages.log 2>&1
echo "fit no-stream rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
grep -E '"(ms_per_step|heldout_psnr|compile_seconds)"' $out/fit_nostreamimages.log >> $out/times.log
cat $out/device.txt $out/times.log
