# Call 2: per-warp pair lists (KernelConfig.mosaic_warp_lists) on the GPU: the forward against
# the block-compacted walk (localgs) and our vanilla kernel per large scene, no gsplat (the
# image's bits against the first row's are printed where they differ), then the compaction's
# tests (bitwise images and gradients, per block and per warp).
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
for s in synthetic10M_4k synthetic4M_1080p guitar_x110_4k guitar_x64_1080p guitar_x16_1080p \
         lego_x16_1080p; do
  left=$(( 420 - ($(date +%s) - t0) )); [ $left -lt 40 ] && break
  timeout $(( left < 100 ? left : 100 )) python3 -m benchmarks.scale --no-gsplat \
    --data carry/data --scenes $s --rows localgs,localgs:warps,vanilla --repeat 10 \
    --csv $out/fwd_$s.csv > $out/fwd_$s.log 2>&1
  echo "$s rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
done
timeout 150 python3 -m pytest -q -p no:cacheprovider -n 4 tests/backends/test_mosaic_staging.py \
  -m 'slow or not slow' -k 'compact or warp' -rf --tb=short > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/times.log; tail -n 3 $out/tests.log
grep -h " e2e " $out/fwd_*.log | cut -c1-140
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
