# Dec 3 fourth session, call 1: A/B of the two unmeasured changes (this tree vs lgs_old at 4a3f59a)
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
q() { grep --line-buffered -v "Warn\|warn\|t = lambda"; }
timeout 100 python3 -m pytest -q -x -p no:cacheprovider tests/test_gaussian_grads.py -k "float32 or twin" 2>&1 | tail -5 > $out/tests.log
for s in guitar_x110_4k guitar_x16_1080p guitar_x64_1080p; do
  timeout 150 python3 carry/ab_pkg.py $s 7 2>&1 | q > $out/ab_$s.log
done
cat $out/tests.log; grep -h "fwd+bwd\|rror" $out/ab_*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
