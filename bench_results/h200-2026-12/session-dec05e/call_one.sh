# One call for a session that may get only one machine start: issue 17's two missed scenes
# with the queued column, then the colour-features render's GPU tests and its cost per pass.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
for spec in synthetic4M_1080p:150 guitar_x110_4k:100; do
  s=${spec%%:*}; t=${spec##*:}
  timeout $t python3 -m benchmarks.scale --data carry/data --scenes $s \
    --rows localgs,vanilla --repeat 20 --big-repeat 20 --csv $out/fwd_$s.csv > $out/fwd_$s.log 2>&1
  echo "fwd $s rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
  grep -v "arn\|lambda\|^device" $out/fwd_$s.log | tail -n 3 | cut -c1-300
done
timeout 120 python3 -m pytest -q -p no:cacheprovider -n 8 tests/test_colors.py \
  tests/backends/test_gradients.py -k "colors or camera" > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; tail -n 4 $out/tests.log
timeout 120 python3 -m benchmarks.features --data carry/data --scene guitar_x16_1080p \
  --channels 1,8,32 --repeat 5 > $out/features.log 2>&1
echo "features rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; cat $out/features.log
cat $out/device.txt $out/times.log
