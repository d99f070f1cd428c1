. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
timeout 250 python3 -m pytest -q -p no:cacheprovider -n 8 -m 'slow or not slow' -rf \
  --tb=short tests/backends/test_backward_segments.py tests/backends/test_gradients.py \
  tests/backends/test_pallas.py tests/backends/test_block_order.py > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
for spec in guitar_720p:150 lego_800:50 guitar_4k:50 guitar_x16_1080p:60 lego_x16_1080p:60 guitar_x64_1080p:70; do
  s=${spec%%:*}; t=${spec##*:}
  timeout $t python3 -m benchmarks.scale --data carry/data --scenes $s \
    --rows localgs,vanilla --repeat 20 --csv $out/fwd_$s.csv > $out/fwd_$s.log 2>&1
  echo "fwd $s rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
done
cat $out/times.log; grep "^FAILED\|passed\|failed\|Timeout" $out/tests.log | tail -5
for f in $out/fwd_*.log; do grep -v "arn\|lambda\|^device" $f | tail -n 3 | cut -c1-200; done
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
