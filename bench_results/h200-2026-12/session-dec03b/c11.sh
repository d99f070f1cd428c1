. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
q() { grep --line-buffered -v "Warn\|warn\|t = lambda"; }
for s in guitar_x16_1080p guitar_x64_1080p; do
  timeout 90 python3 -m benchmarks.scale --grad --no-gsplat --data carry/data --scenes $s \
    --rows localgs,localgs@walked --repeat 5 --csv $out/grad_$s.csv 2>&1 | q > $out/grad_$s.log
done
XLA_FLAGS="--xla_dump_to=/tmp/hlo --xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*jit_loss.*" \
  timeout 120 python3 -m benchmarks.scale --grad --no-gsplat --data carry/data \
  --scenes guitar_x110_4k --rows localgs@walked,localgs --repeat 5 --csv $out/grad_guitar_x110_4k.csv 2>&1 | q > $out/grad_guitar_x110_4k.log
grep -h "grad:" $out/grad_*.log
timeout 170 python3 carry/cmp.py guitar_x110_4k 2>&1 | q | tee $out/cmp_x110.log
mkdir -p $out/hlo
for f in /tmp/hlo/*jit_loss*after_optimizations.txt; do
  p="${f%.txt}"; b=$(basename $p)
  python3 scripts/hlo_peak.py "$p" --top 60 > "$out/hlo/$b.peak.txt" 2>&1
  python3 scripts/hlo_peak.py "$p" --top 60 --temp > "$out/hlo/$b.temp_peak.txt" 2>&1
  tar czf "$out/hlo/$b.tgz" -C /tmp/hlo "$b.txt" "$b-buffer-assignment.txt" "$b-live-range.txt" "$b-memory-usage-report.txt"
done
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
