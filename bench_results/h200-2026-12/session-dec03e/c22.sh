# call 2: A/B vs 387d23a at x64 and x110 (grad walked/default, forward)
. scripts/gpu_env.sh
for s in guitar_x64_1080p guitar_x110_4k; do
  timeout 150 python3 carry/ab_pkg.py $s 7 2>&1 | grep -v Warn > $out/ab_$s.log
  timeout 100 python3 carry/ab_pkg.py $s 10 fwd 2>&1 | grep -v Warn > $out/abf_$s.log
done
grep "same bits\|rror" $out/ab*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
