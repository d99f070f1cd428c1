# Call 3: issue 18's table for lego x16 and the small scenes at this tree (walked rows, gsplat
# 1.5.3 in the same process), then skull training 3k steps, da62541's tree (before 602cc56
# and sh_sums) and this one, each in its own process (ms per step, peak memory).
. scripts/gpu_env.sh
base=$out; t0=$(date +%s)
OUT=$base/grad SCENES="lego_x16_1080p lego_800 guitar_720p guitar_4k" \
  GRAD_ROWS=localgs@walked SCENE_TIMEOUT=90 bash scripts/scale_gpu_check.sh grad \
  > $base/grad.log 2>&1
echo "grad $(( $(date +%s) - t0 )) s" >> $base/times.log
export LGS_JAX_CACHE="$PWD/build/jax_cache"
for tree in old head; do
  pp=$PYTHONPATH; [ $tree = head ] || pp="$PWD/carry/old/tree_da62541:$pp"
  PYTHONPATH=$pp timeout 150 python3 benchmarks/train_vs_gsplat.py --data-root carry/data \
    --scenes skull --steps 3000 --eval-every 3000 --no-gsplat --out $base/skull_$tree \
    > $base/skull_$tree.log 2>&1
  echo "skull $tree $(( $(date +%s) - t0 )) s" >> $base/times.log
done
cat $base/times.log; cat $base/grad.log | grep -v "^\s*$" | tail -12
tail -n 2 $base/skull_old/summary.csv $base/skull_head/summary.csv
tar czf /tmp/all.tgz -C $base . && rm -rf $base/* && mv /tmp/all.tgz $base/
