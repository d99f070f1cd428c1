# sums in place + the projection barrier's identity derivative: tests, forward + backward with
# gsplat in the same process (x16 and x110 dumped), then the 4K forward's kernels (no gsplat)
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
q() { grep --line-buffered -v "Warn\|warn\|t = lambda"; }
timeout 150 python3 -m pytest -q -p no:cacheprovider -n 8 tests/backends/test_gaussian_grads.py \
  tests/backends/test_backward_segments.py tests/backends/test_gradients.py tests/test_projection.py \
  -m 'slow or not slow' -rf --tb=short > $out/tests.log 2>&1; grep "^FAILED\|passed\|failed" $out/tests.log
timeout 200 python3 -c "from gsplat.cuda._backend import _C; assert _C is not None" 2>&1 | grep "rror" | tail -3
for s in guitar_x16_1080p guitar_x64_1080p guitar_x110_4k; do
  d=""; [ $s != guitar_x64_1080p ] && d="--xla_dump_to=/tmp/hlo_$s --xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*jit_loss.*"
  XLA_FLAGS="$d" timeout 100 python3 -m benchmarks.scale --grad --data carry/data --scenes $s \
    --rows localgs,localgs@walked --repeat 5 --csv $out/grad_$s.csv 2>&1 | q > $out/grad_$s.log
done
XLA_FLAGS="--xla_dump_to=/tmp/hlo_fwd720 --xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*lambda.*" \
  timeout 60 python3 -m benchmarks.scale --no-gsplat --data carry/data --scenes guitar_720p \
  --rows localgs --repeat 3 2>&1 | q > $out/fwd_720p.log
mkdir -p $out/hlo
for f in /tmp/hlo_*/*jit_loss*after_optimizations.txt /tmp/hlo_fwd720/*after_optimizations.txt; do
  p="${f%.txt}"; b=$(basename $(dirname $p))_$(basename $p); dd=$(dirname $p)
  python3 scripts/hlo_peak.py "$p" --top 50 > "$out/hlo/$b.peak.txt" 2>&1
  python3 scripts/hlo_peak.py "$p" --top 50 --temp > "$out/hlo/$b.temp_peak.txt" 2>&1
  tar czf "$out/hlo/$b.tgz" -C $dd $(cd $dd; ls $(basename $p)*)
done
timeout 120 python3 scripts/kernel_times.py --data carry/data --scenes guitar_x110_4k --rows localgs \
  --iters 5 --top 40 --no-gsplat 2>&1 | q > $out/kernels_x110.log
grep -h "grad:" $out/grad_*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
