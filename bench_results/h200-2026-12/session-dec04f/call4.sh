# Call 4: with per-warp lists the default, the GPU tests of the kernels and gradients (the
# split backward, gradients, staging and compaction, the Pallas backends), then
# forward + backward against the block-compacted walk at two scenes (rows at the walked pairs).
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
quiet() { grep --line-buffered -v "Warning\|warn(\|t = lambda"; }
timeout 360 python3 -m pytest -q -p no:cacheprovider -n 8 -m 'slow or not slow' -rf \
  --tb=short tests/backends/test_backward_segments.py \
  tests/backends/test_gradients.py tests/backends/test_mosaic_staging.py \
  tests/backends/test_pallas.py > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
for s in synthetic4M_1080p guitar_x110_4k; do
  left=$(( 540 - ($(date +%s) - t0) )); [ $left -lt 40 ] && break
  timeout $(( left < 100 ? left : 100 )) python3 -m benchmarks.scale --grad --no-gsplat \
    --data carry/data --scenes $s --rows localgs@walked,localgs:blocks@walked --repeat 5 \
    --csv $out/grad_$s.csv 2>&1 | quiet > $out/grad_$s.log
  echo "$s rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
done
cat $out/times.log; grep "^FAILED\|passed\|failed" $out/tests.log | tail -5
grep -h "grad:\|fwd+bwd" $out/grad_*.log | cut -c1-150
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
