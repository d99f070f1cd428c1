# call 1: the whole forward benchmark (issue 17's table, gsplat in the same process), then the
# synthetic scenes' forward + backward against gsplat (issue 18's worst rows)
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache" TORCH_EXTENSIONS_DIR="$PWD/build/torch_extensions"
timeout 240 python3 -c "from gsplat.cuda._backend import _C" 2>&1 | grep "set up\|rror" > $out/gsplat_build.log
( time timeout $((440 - SECONDS)) python3 -m benchmarks.scale --data carry/data --csv $out/full.csv ) 2>&1 | grep -v "Warn\|warn(\|t = lambda" > $out/full.log
for s in synthetic4M_1080p synthetic10M_4k; do
  timeout $((575 - SECONDS)) python3 -m benchmarks.scale --grad --data carry/data --scenes $s --rows localgs,localgs@walked --repeat 5 --csv $out/grad_$s.csv 2>&1 | grep -v "Warn\|warn(\|t = lambda" > $out/grad_$s.log
done
cat $out/gsplat_build.log; grep -h " e2e \|real" $out/full.log | cut -c1-175; grep -h "grad:" $out/grad_*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
