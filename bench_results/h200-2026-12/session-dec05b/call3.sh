. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
for spec in guitar_x110_4k:150 synthetic4M_1080p:120; do
  s=${spec%%:*}; t=${spec##*:}
  timeout $t python3 -m benchmarks.scale --data carry/data --scenes $s --grad --no-gsplat \
    --rows localgs@walked,localgs:buckets@walked --repeat 10 --big-repeat 10 --csv $out/grad_$s.csv > $out/grad_$s.log 2>&1
  echo "grad $s rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
done
for m in no-stream-images stream-images uint8-images; do
  timeout 100 python3 -m lgs_jax fit --data carry/data/skull --steps 3000 --eval-every 3000 --$m \
    --out /tmp/s_$m > $out/fit_$m.log 2>&1
  echo "fit $m rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
done
cat $out/times.log; for f in $out/grad_*.log; do echo "== $f"; grep -v "arn\|lambda" $f | tail -n 4 | cut -c1-200; done
for f in $out/fit_*.log; do echo "== $f"; grep -E "ms_per_step|heldout_psnr|compile" $f | tail -n 4 | cut -c1-200; done
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
