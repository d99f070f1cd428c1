# Call two: the features benchmark again (call one's timed host copies of the scene), the
# colours tests after the tolerance fix, whether the blocked forward's host time is XLA
# re-recording command buffers (scripts/donate_probe.py), issue 17's guitar x110 4K row again.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
timeout 90 python3 -m pytest -q -p no:cacheprovider -n 8 tests/test_colors.py > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; tail -n 2 $out/tests.log
timeout 150 python3 -m benchmarks.features --data carry/data --scene guitar_x16_1080p \
  --channels 1,8,32 --repeat 10 > $out/features.log 2>&1
echo "features rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; cat $out/features.log
timeout 120 python3 scripts/donate_probe.py --data carry/data > $out/donate.log 2>&1
echo "donate rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; grep -v "arn" $out/donate.log
timeout 150 python3 -m benchmarks.scale --data carry/data --scenes guitar_x110_4k \
  --rows localgs,vanilla --repeat 20 --big-repeat 20 --csv $out/fwd.csv > $out/fwd.log 2>&1
echo "fwd guitar_x110_4k rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
grep -v "arn\|lambda\|^device" $out/fwd.log | tail -n 3 | cut -c1-300
cat $out/device.txt $out/times.log
