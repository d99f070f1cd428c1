# Call 4: skull training 3k steps, da62541's tree (before 602cc56 and sh_sums) and this one,
# each in its own process (ms per step, peak memory); then Nsight Compute on one launch of the
# Local-GS and vanilla forward kernels at synthetic 4M (issue 17: where each spends its time).
. scripts/gpu_env.sh
base=$out; t0=$(date +%s)
export LGS_JAX_CACHE="$PWD/build/jax_cache"
for tree in old head; do
  pp=$PYTHONPATH; [ $tree = head ] || pp="$PWD/carry/old/tree_da62541:$pp"
  PYTHONPATH=$pp timeout 150 python3 benchmarks/train_vs_gsplat.py --data-root carry/data \
    --scenes skull --steps 3000 --eval-every 3000 --no-gsplat --out $base/skull_$tree \
    > $base/skull_$tree.log 2>&1
  echo "skull $tree $(( $(date +%s) - t0 )) s" >> $base/times.log
done
left=$(( 550 - ($(date +%s) - t0) ))
PYTHONPATH=$PWD timeout $left ncu --clock-control none -k regex:'localgs_kernel|vanilla' -c 2 \
  --set full python3 scripts/ncu_localgs.py carry/data --scene synthetic4M_1080p \
  --backends pallas,pallas_vanilla --kernel mosaic > $base/ncu_fwd_syn4M.txt 2>&1
echo "ncu $(( $(date +%s) - t0 )) s" >> $base/times.log
cat $base/times.log; tail -n 2 $base/skull_old/summary.csv $base/skull_head/summary.csv
grep -E "^  [a-z_]+.*\(|Duration|Registers Per|Achieved Occupancy|Executed Ipc A|Elapsed Cycles" \
  $base/ncu_fwd_syn4M.txt | head -30
tar czf /tmp/all.tgz -C $base . && rm -rf $base/* && mv /tmp/all.tgz $base/
