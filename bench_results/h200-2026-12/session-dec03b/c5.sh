. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
timeout 330 python3 -m pytest -q -p no:cacheprovider -n 8 tests/backends/test_backward_segments.py \
  tests/backends/test_gaussian_grads.py tests/backends/test_gradients.py \
  -k "zero_depth or split or compact or walked or row_capacity or twin or pallas_gradients" \
  -m 'slow or not slow' -rf --tb=short > $out/tests.log 2>&1
grep "^FAILED\|passed\|failed" $out/tests.log
XLA_FLAGS="--xla_dump_to=/tmp/hlo --xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*jit_loss.*" \
  timeout 150 python3 -m benchmarks.scale --grad --no-gsplat --data carry/data \
  --scenes guitar_x110_4k --rows localgs@walked,localgs --repeat 5 2>&1 | grep "grad:" | tee $out/dump_grad.log
mkdir -p $out/hlo
for f in /tmp/hlo/*jit_loss*after_optimizations.txt; do
  p="${f%.txt}"; python3 scripts/hlo_peak.py "$p" --top 40 > "$out/hlo/$(basename $p).peak.txt" 2>&1
  cp "$p-memory-usage-report.txt" "$out/hlo/" 2>/dev/null
done
head -n 12 $out/hlo/*.peak.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
