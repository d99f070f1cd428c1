# call 1: the kernels' GPU tests (13-column table staged by Mosaic GPU), then A/B vs 387d23a at x16
. scripts/gpu_env.sh
TEST_WORKERS=8 TEST_TIMEOUT=330 bash scripts/scale_gpu_check.sh tests > $out/tests_summary.txt 2>&1
for s in guitar_x16_1080p; do
  timeout 120 python3 carry/ab_pkg.py $s 7 2>&1 | grep -v Warn > $out/ab_$s.log
  timeout 90 python3 carry/ab_pkg.py $s 10 fwd 2>&1 | grep -v Warn > $out/abf_$s.log
done
cat $out/tests_summary.txt; grep "same bits\|rror" $out/ab*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
