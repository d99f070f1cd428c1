# call 8 (last seconds of the budget): the split backward's entries on the GPU: A/B at 0.09M 4K, then its tests
. scripts/gpu_env.sh
timeout 75 python3 carry/ab_pkg.py guitar_4k 5 2>&1 | grep --line-buffered -v Warn | tee $out/ab_guitar_4k.log
timeout 100 python3 -m pytest -q -x -p no:cacheprovider -n 8 tests/backends/test_backward_segments.py -m 'slow or not slow' 2>&1 | tail -3 | tee $out/tests.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
