# Call four (the last start the budget allows, about 200 s of run): the host-time probe at
# guitar x110 4K, where the blocked call's host share is largest, then the features benchmark
# at one channel count if time remains.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
timeout 100 python3 scripts/donate_probe.py --data carry/data --scenes guitar_x110_4k \
  synthetic4M_1080p --repeat 20 > $out/donate.log 2>&1
echo "donate rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; grep -v "arn" $out/donate.log
timeout 70 python3 -m benchmarks.features --data carry/data --scene guitar_x16_1080p \
  --channels 8,32 --repeat 5 --no-grad > $out/features.log 2>&1
echo "features rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; cat $out/features.log
cat $out/device.txt $out/times.log
