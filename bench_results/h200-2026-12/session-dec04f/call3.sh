# Call 3: issue 17's forward table with per-warp lists the default (localgs), gsplat 1.5.3 in
# the same process: the six large scenes with the Local-GS loop unrolled 4 times beside the
# default 8 and our vanilla kernel, then the three small scenes against the block-compacted walk.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
quiet() { grep --line-buffered -v "Warning\|warn(\|t = lambda"; }
timeout 240 python3 -c "from gsplat.cuda._backend import _C; assert _C is not None" 2>&1 \
  | grep "rror" > $out/gsplat_build.log
echo "gsplat $(( $(date +%s) - t0 )) s" >> $out/times.log
run() {  # scene, rows
  left=$(( 540 - ($(date +%s) - t0) )); [ $left -lt 30 ] && return
  timeout $(( left < 100 ? left : 100 )) python3 -m benchmarks.scale --data carry/data \
    --scenes $1 --rows $2 --repeat 10 --csv $out/fwd_$1.csv 2>&1 | quiet > $out/fwd_$1.log
  echo "$1 rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
}
for s in synthetic10M_4k synthetic4M_1080p guitar_x110_4k guitar_x64_1080p guitar_x16_1080p \
         lego_x16_1080p; do run $s localgs,localgs:unroll4,vanilla; done
for s in guitar_720p guitar_4k lego_800; do run $s localgs,localgs:blocks; done
cat $out/times.log
grep -h " e2e " $out/fwd_*.log | sed 's/ proj .*MiB pairs/ ... MiB pairs/' | cut -c1-150
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
