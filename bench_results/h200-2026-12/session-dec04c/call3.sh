# Call 3: skull 3k steps, seeds 2-4, this tree and tree_ff6056a (5831554's training bits), six
# processes at once (the PSNRs are deterministic; the step times of this call mean nothing);
# then unroll 4 against 8 in the forward.
. scripts/gpu_env.sh
t0=$(date +%s)
for seed in 2 3 4; do
  for tree in head tree_ff6056a; do
    pp=$PYTHONPATH; [ $tree = head ] || pp="$PWD/carry/old/$tree:$PYTHONPATH"
    PYTHONPATH=$pp timeout 400 python3 benchmarks/train_vs_gsplat.py --data-root carry/data \
      --scenes skull --steps 3000 --eval-every 3000 --seed $seed --no-gsplat \
      --out $out/skull_${tree}_$seed > $out/skull_${tree}_$seed.log 2>&1 &
  done
done
wait
echo "training $(( $(date +%s) - t0 )) s" >> $out/times.log
for f in $out/skull_*.log; do echo "$(basename $f .log): $(tail -1 $f)"; done | tee $out/summary.txt
left=$(( 560 - ($(date +%s) - t0) ))
timeout $left python3 -m benchmarks.scale --no-gsplat --data carry/data --scenes \
  synthetic4M_1080p,guitar_x64_1080p --rows localgs,localgs:unroll4 --repeat 10 \
  > $out/unroll.log 2>&1
echo "unroll $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/times.log; grep " e2e \|raster" $out/unroll.log | tail -12
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
