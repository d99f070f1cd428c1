# call 2: A/B vs cdc3380 (before the split backward's entries) at 0.09M 720p and 1.45M-10M
. scripts/gpu_env.sh
for s in guitar_720p guitar_x16_1080p guitar_x64_1080p guitar_x110_4k; do
  timeout 130 python3 carry/ab_pkg.py $s 7 2>&1 | grep -v Warn > $out/ab_$s.log; done
grep "same bits\|rror" $out/ab*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
