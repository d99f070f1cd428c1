# call 3: a full benchmarks.scale run (every scene and row, gsplat in the same process), timed
# against issue 17's 10-minute bound; lines come per scene, so a cut run says how far it got
. scripts/gpu_env.sh; export LGS_JAX_CACHE=$PWD/build/jax_cache
start=$(date +%s)
timeout 575 python3 -m benchmarks.scale --data carry/data --csv $out/full.csv 2>&1 | grep --line-buffered -v "Warn\|warn(" > $out/full.log
echo "rc ${PIPESTATUS[0]} elapsed $(( $(date +%s) - start )) s" | tee -a $out/full.log
tail -40 $out/full.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
