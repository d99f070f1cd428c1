# call 3: command-buffer probe; 4K forward vs gsplat; whole-tile backward at 1080p
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
q() { grep --line-buffered -v "Warn\|warn\|t = lambda"; }
for s in guitar_x110_4k guitar_x16_1080p guitar_720p; do
  timeout 80 python3 carry/cb_probe.py $s 15 2>&1 | q > $out/cb_$s.log; done
timeout 100 python3 -m benchmarks.scale --grad --no-gsplat --data carry/data --scenes guitar_x16_1080p \
  --rows localgs@walked,localgs:bwd256@walked --repeat 7 2>&1 | q > $out/whole_x16.log
timeout 200 python3 -m benchmarks.scale --data carry/data --scenes guitar_x110_4k --rows localgs --repeat 10 2>&1 | q > $out/fwd_x110.log
grep -h "wall\|failed" $out/cb_*.log; grep -v "^\s*$" $out/whole_x16.log | tail -6; grep -v "^\s*$" $out/fwd_x110.log | tail -8
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
