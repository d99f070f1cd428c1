. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
timeout 300 python3 carry/cmp.py guitar_x110_4k 2>&1 | grep -v "Warn\|warn" | tee $out/cmp_x110.log
timeout 200 python3 carry/bis.py guitar_x110_4k new,newwalked 2>&1 | grep -v "Warn\|warn" | tee $out/bis_x110.log
