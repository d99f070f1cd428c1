# Call 1: skull 3000 steps in the streaming modes (threaded copies since a13af12) and with the
# bilateral grid, then the GPU run of the multi-size and bilateral-grid tests.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
python3 -c "import jax; print(jax.__version__, jax.devices())" >> $out/device.txt 2>&1
for m in "no-stream-images" "stream-images" "stream-images --uint8-images" \
         "no-stream-images --bilateral-grid"; do
  n=$(echo $m | tr -d ' -'); timeout 120 python3 -m lgs_jax fit --data carry/data/skull \
    --steps 3000 --eval-every 3000 --$m --out /tmp/s_$n > $out/fit_$n.log 2>&1
  echo "fit $m rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
  grep -E '"(ms_per_step|heldout_psnr|compile_seconds)"' $out/fit_$n.log >> $out/times.log
done
timeout 170 python3 -m pytest -q -p no:cacheprovider -n 4 -rf --tb=short \
  tests/train/test_sizes.py tests/train/test_bilateral_grid.py > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/device.txt $out/times.log; grep "^FAILED\|passed\|failed\|Timeout" $out/tests.log | tail -8
