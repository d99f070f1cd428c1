# call 2: whole-tile backward at 1080p; 4K forward kernels; aliasing test on GPU
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
q() { grep --line-buffered -v "Warn\|warn\|t = lambda"; }
T=$(grep -rln "writing_into_the_layouts" tests | head -1)
timeout 100 python3 -m pytest -q -x -p no:cacheprovider $T -k "float32 or twin" 2>&1 | tail -3 > $out/tests.log
for s in guitar_x16_1080p guitar_x64_1080p; do
timeout 130 python3 -m benchmarks.scale --grad --no-gsplat --data carry/data --scenes $s \
  --rows localgs@walked,localgs:bwd256@walked,localgs:px256@walked,localgs,localgs:px256 --repeat 7 2>&1 | q > $out/whole_$s.log
done
timeout 120 python3 scripts/kernel_times.py --data carry/data --scenes guitar_x110_4k --rows localgs --iters 5 --top 40 --no-gsplat 2>&1 | q > $out/kt_x110.log
cat $out/tests.log; tail -8 $out/whole_*.log; tail -50 $out/kt_x110.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
