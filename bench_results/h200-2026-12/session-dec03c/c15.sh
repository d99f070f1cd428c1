# A/B in one process: this session's sums-in-place + identity-derivative barrier against HEAD
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
q() { grep --line-buffered -v "Warn\|warn\|t = lambda"; }
timeout 120 python3 carry/ab3.py --grad --no-gsplat --data carry/data --scenes guitar_x110_4k \
  --rows "localgs#new@walked,localgs#old@walked,localgs#new,localgs#old" --repeat 7 2>&1 | q > $out/ab_x110.log
timeout 60 python3 carry/ab3.py --grad --no-gsplat --data carry/data --scenes guitar_x16_1080p \
  --rows "localgs#new@walked,localgs#old@walked" --repeat 7 2>&1 | q > $out/ab_x16.log
grep -h "grad:\|rror" $out/ab_*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
