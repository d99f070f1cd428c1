# sums_in_place.patch: its tests, then forward + backward with gsplat in the same process, x110 dumped
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
q() { grep --line-buffered -v "Warn\|warn\|t = lambda"; }
timeout 160 python3 -m pytest -q -p no:cacheprovider -n 8 tests/backends/test_gaussian_grads.py \
  tests/backends/test_backward_segments.py tests/backends/test_gradients.py -m 'slow or not slow' \
  -rf --tb=short > $out/tests.log 2>&1; grep "^FAILED\|passed\|failed" $out/tests.log
timeout 200 python3 -c "from gsplat.cuda._backend import _C; assert _C is not None" 2>&1 | grep "rror" | tail -3
for s in guitar_x16_1080p guitar_x64_1080p; do
  timeout 85 python3 -m benchmarks.scale --grad --data carry/data --scenes $s \
    --rows localgs,localgs@walked --repeat 5 --csv $out/grad_$s.csv 2>&1 | q > $out/grad_$s.log
done
XLA_FLAGS="--xla_dump_to=/tmp/hlo --xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*jit_loss.*" \
  timeout 110 python3 -m benchmarks.scale --grad --data carry/data \
  --scenes guitar_x110_4k --rows localgs@walked,localgs --repeat 5 --csv $out/grad_guitar_x110_4k.csv 2>&1 | q > $out/grad_guitar_x110_4k.log
mkdir -p $out/hlo
for f in /tmp/hlo/*jit_loss*after_optimizations.txt; do
  p="${f%.txt}"; b=$(basename $p)
  python3 scripts/hlo_peak.py "$p" --top 60 --temp > "$out/hlo/$b.temp_peak.txt" 2>&1
  tar czf "$out/hlo/$b.tgz" -C /tmp/hlo "$b.txt" "$b-buffer-assignment.txt" "$b-live-range.txt" "$b-memory-usage-report.txt"
done
grep -h "grad:" $out/grad_*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
