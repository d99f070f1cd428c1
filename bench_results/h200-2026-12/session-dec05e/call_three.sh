# Call three (call two cut to the device time left): whether the blocked forward's host time
# is XLA re-recording command buffers (scripts/donate_probe.py), then the features benchmark
# again (call one's timed host copies of the scene).
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
timeout 130 python3 scripts/donate_probe.py --data carry/data --repeat 20 > $out/donate.log 2>&1
echo "donate rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; grep -v "arn" $out/donate.log
timeout 100 python3 -m benchmarks.features --data carry/data --scene guitar_x16_1080p \
  --channels 1,8,32 --repeat 5 > $out/features.log 2>&1
echo "features rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; cat $out/features.log
cat $out/device.txt $out/times.log
