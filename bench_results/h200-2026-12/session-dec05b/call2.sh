. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
for spec in synthetic10M_4k:210 guitar_x110_4k:140 synthetic4M_1080p:130; do
  s=${spec%%:*}; t=${spec##*:}
  timeout $t python3 -m benchmarks.scale --data carry/data --scenes $s \
    --rows localgs,localgs:buckets,vanilla --repeat 20 --big-repeat 20 --csv $out/fwd_$s.csv > $out/fwd_$s.log 2>&1
  echo "fwd $s rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
done
cat $out/times.log; for f in $out/fwd_*.log; do echo "== $f"; tail -n 8 $f | cut -c1-200; done
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
