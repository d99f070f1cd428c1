# Call 3: the final sh_sums (3724a2a) against 4ebdd1c at lego x16 (bits, time, memory), then
# issue 18's table for lego x16 and the small scenes at this tree (walked rows, gsplat 1.5.3 in
# the same process).
. scripts/gpu_env.sh
base=$out; t0=$(date +%s)
timeout 130 python3 -m benchmarks.ab run lego_x16_1080p --old carry/old --revs 4ebdd1c \
  --repeat 7 --data carry/data > $base/ab_legox16.log 2>&1
echo "ab $(( $(date +%s) - t0 )) s" >> $base/times.log
OUT=$base/grad SCENES="lego_x16_1080p lego_800 guitar_720p guitar_4k" \
  GRAD_ROWS=localgs@walked SCENE_TIMEOUT=90 bash scripts/scale_gpu_check.sh grad \
  > $base/grad.log 2>&1
echo "grad $(( $(date +%s) - t0 )) s" >> $base/times.log
cat $base/ab_legox16.log $base/times.log; grep -v "^\s*$" $base/grad.log | tail -12
tar czf /tmp/all.tgz -C $base . && rm -rf $base/* && mv /tmp/all.tgz $base/
