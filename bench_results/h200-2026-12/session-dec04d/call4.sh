# Call 4: issue 18's training throughput at this tree (7k steps each, defaults, no gsplat):
# Lego 200x200, then skull at full size; then, with what time is left, every kernel of our
# synthetic 4M forward (no gsplat).
. scripts/gpu_env.sh
base=$out; t0=$(date +%s)
OUT=$base/lego TRAIN_SCENES=lego TRAIN_TIMEOUT=200 bash scripts/scale_gpu_check.sh train \
  > $base/train_lego.txt 2>&1
echo "lego $(( $(date +%s) - t0 )) s" >> $base/times.log
OUT=$base/skull TRAIN_SCENES=skull TRAIN_TIMEOUT=$(( 500 - ($(date +%s) - t0) )) \
  bash scripts/scale_gpu_check.sh train > $base/train_skull.txt 2>&1
echo "skull $(( $(date +%s) - t0 )) s" >> $base/times.log
left=$(( 560 - ($(date +%s) - t0) ))
[ $left -gt 30 ] && timeout $left python3 scripts/kernel_times.py --data carry/data \
  --scenes synthetic4M_1080p --rows localgs --iters 5 --top 30 --no-gsplat \
  > $base/kernels_syn4M.log 2>&1
echo "kernels $(( $(date +%s) - t0 )) s" >> $base/times.log
cat $base/times.log; tail -n 4 $base/train_lego.txt $base/train_skull.txt
grep -v "Warn\|warn" $base/kernels_syn4M.log | tail -34
tar czf /tmp/all.tgz -C $base . && rm -rf $base/* && mv /tmp/all.tgz $base/
