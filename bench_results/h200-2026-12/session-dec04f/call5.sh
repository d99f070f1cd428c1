# Call 5: issue 17's forward rows where call 3 missed or met 0.8x narrowly, 20 rounds, gsplat
# 1.5.3 in the same process: Local-GS (per-warp lists, the default) and our vanilla kernel.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
quiet() { grep --line-buffered -v "Warning\|warn(\|t = lambda"; }
timeout 240 python3 -c "from gsplat.cuda._backend import _C; assert _C is not None" 2>&1 \
  | grep "rror" > $out/gsplat_build.log
echo "gsplat $(( $(date +%s) - t0 )) s" >> $out/times.log
for s in synthetic4M_1080p guitar_x110_4k synthetic10M_4k lego_x16_1080p guitar_4k; do
  left=$(( 440 - ($(date +%s) - t0) )); [ $left -lt 30 ] && break
  timeout $(( left < 90 ? left : 90 )) python3 -m benchmarks.scale --data carry/data \
    --scenes $s --rows localgs,vanilla --repeat 20 --csv $out/fwd_$s.csv 2>&1 | quiet \
    > $out/fwd_$s.log
  echo "$s rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
done
cat $out/times.log
grep -h " e2e " $out/fwd_*.log | sed 's/ proj .*MiB pairs/ ... MiB pairs/' | cut -c1-150
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
