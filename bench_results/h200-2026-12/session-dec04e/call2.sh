# Call 2: the SH cotangent as one broadcast product (sh.sh_sums) against 4ebdd1c (the 48-way
# concatenate, call 1: 5.42 against da62541's 4.93 ms), 602cc56 and da62541 at lego x16; the
# SH-degree-0 synthetic 4M against 602cc56 (d8be94b's select alone); every kernel of the lego
# x16 gradient at this tree.
. scripts/gpu_env.sh
t0=$(date +%s)
timeout 240 python3 -m benchmarks.ab run lego_x16_1080p --old carry/old \
  --revs da62541,602cc56,4ebdd1c --repeat 7 --data carry/data > $out/ab_legox16.log 2>&1
echo "ab lego $(( $(date +%s) - t0 )) s" >> $out/times.log
timeout 150 python3 -m benchmarks.ab run synthetic4M_1080p --old carry/old \
  --revs 602cc56,4ebdd1c --repeat 7 --data carry/data > $out/ab_syn4M.log 2>&1
echo "ab syn4M $(( $(date +%s) - t0 )) s" >> $out/times.log
timeout 120 python3 scripts/kernel_times.py --data carry/data --scenes lego_x16_1080p --grad \
  --no-gsplat --top 20 > $out/kt_legox16_grad.log 2>&1
echo "kt $(( $(date +%s) - t0 )) s" >> $out/times.log
head -40 $out/kt_legox16_grad.log; cat $out/ab_legox16.log $out/ab_syn4M.log $out/times.log
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
