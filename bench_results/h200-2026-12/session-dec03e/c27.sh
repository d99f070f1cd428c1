# call 7: the 4K forward again, 20 alternating rounds (localgs and gsplat only)
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache" TORCH_EXTENSIONS_DIR="$PWD/build/torch_extensions"
timeout 150 python3 -m benchmarks.scale --data carry/data --scenes guitar_x110_4k --rows localgs --repeat 20 2>&1 | grep -v Warn > $out/fwd20_x110.log
grep " e2e " $out/fwd20_x110.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
