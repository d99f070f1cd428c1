. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
timeout 200 python3 carry/bis.py guitar_x16_1080p old,new,newdepth,new-nobarrier,oldwalked,newwalked 2>&1 | grep -v "Warn\|warn" | tee $out/bis_x16.log
timeout 200 python3 carry/bis.py guitar_x110_4k old,new,newdepth,new-nobarrier 2>&1 | grep -v "Warn\|warn" | tee $out/bis_x110.log
XLA_FLAGS="--xla_dump_to=/tmp/hlo --xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*jit_loss.*" \
  timeout 150 python3 -m benchmarks.scale --grad --no-gsplat --data carry/data \
  --scenes guitar_x110_4k --rows localgs@walked,localgs --repeat 5 2>&1 | grep -v "Warn\|warn" | tee $out/dump_grad.log
mkdir -p $out/hlo
for f in /tmp/hlo/*jit_loss*after_optimizations.txt; do
  p="${f%.txt}"; python3 scripts/hlo_peak.py "$p" --top 60 > "$out/hlo/$(basename $p).peak.txt" 2>&1
  python3 scripts/hlo_peak.py "$p" --top 0 --timeline > "$out/hlo/$(basename $p).timeline.txt" 2>&1
  gzip -c "$f" > "$out/hlo/$(basename $f).gz"
done
head -n 6 $out/hlo/*.peak.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
