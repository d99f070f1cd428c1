. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
python3 -c "import jax; print(jax.__version__, jax.devices())" >> $out/device.txt 2>&1
timeout 290 python3 -m pytest -q -p no:cacheprovider -n 8 -m 'slow or not slow' -rf \
  --tb=short tests/backends/test_backward_segments.py tests/backends/test_gradients.py \
  tests/backends/test_mosaic_staging.py tests/backends/test_pallas.py \
  tests/backends/test_mosaic_inline.py > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
timeout 210 python3 -m benchmarks.render_vs_gsplat --data carry/data --scene guitar@1280x720 \
  --scene lego_sh3@800x800 --rows pallas --repeat 5 --antialiased > $out/antialiased.log 2>&1
echo "antialiased rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/device.txt $out/times.log; grep "^FAILED\|passed\|failed\|Timeout" $out/tests.log | tail -8
grep -v "^\s*$" $out/antialiased.log | tail -n 6 | cut -c1-220
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
