# call 2: forward + backward against gsplat on the captures and their densified copies
# (issue 18's table; the synthetic rows are call 1's)
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
timeout 240 python3 -c "from gsplat.cuda._backend import _C" 2>&1 | grep "set up\|rror" > $out/gsplat_build.log
for s in guitar_x110_4k guitar_x64_1080p guitar_x16_1080p guitar_4k guitar_720p lego_800 lego_x16_1080p; do
  left=$((560 - SECONDS)); [ $left -lt 30 ] && break
  timeout $left python3 -m benchmarks.scale --grad --data carry/data --scenes $s --rows localgs,localgs@walked --repeat 5 --csv $out/grad_$s.csv 2>&1 | grep -v "Warn\|warn(\|t = lambda" > $out/grad_$s.log
  echo "$s done at $SECONDS s" >> $out/progress.log
done
cat $out/gsplat_build.log $out/progress.log; grep -h "grad:" $out/grad_*.log | cut -c1-160
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
