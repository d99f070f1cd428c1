# call 4: host events of the 4K forward; whole-tile backward blocks at 720p, 800x800, x64 1080p
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
q() { grep --line-buffered -v "Warn\|warn\|t = lambda"; }
timeout 100 python3 scripts/kernel_times.py --data carry/data --scenes guitar_x110_4k --rows localgs --iters 5 --top 6 --host 90 --no-gsplat 2>&1 | q > $out/kt_host.log
for s in guitar_720p lego_800 guitar_4k guitar_x64_1080p; do
timeout 120 python3 -m benchmarks.scale --grad --no-gsplat --data carry/data --scenes $s \
  --rows localgs,localgs:bwd256 --repeat 7 2>&1 | q > $out/whole_$s.log
done
grep -h "fwd+bwd" $out/whole_*.log; grep -A90 "host events" $out/kt_host.log | grep -v "\\$" | head -70
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
