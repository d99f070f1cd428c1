# call 1: the GPU tests of the three unrun kernel changes (e20efcf, 1a5e9ba, dc63f59) with the
# lean defaults, then in-process A/B against the package at bdedc32 (carry/ab_pkg.py =
# session-dec03e/ab_pkg.py; carry/old/lgs_old from `git archive bdedc32 lgs_jax`, renamed)
. scripts/gpu_env.sh
TEST_WORKERS=8 TEST_TIMEOUT=240 bash scripts/scale_gpu_check.sh tests > $out/tests_summary.txt 2>&1
timeout 70 python3 carry/ab_pkg.py guitar_4k 9 fwd 2>&1 | grep -v Warn > $out/ab_guitar_4k_fwd.log
timeout 120 python3 carry/ab_pkg.py guitar_x64_1080p 7 2>&1 | grep -v Warn > $out/ab_guitar_x64_1080p.log
timeout $((575 - SECONDS)) python3 carry/ab_pkg.py synthetic4M_1080p 5 2>&1 | grep -v Warn > $out/ab_synthetic4M_1080p.log
cat $out/tests_summary.txt; grep "same bits\|rror" $out/ab*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
