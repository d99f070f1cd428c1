# call 5 (last of the budget): every kernel's time at synthetic 10M 4K, forward, ours and gsplat's
. scripts/gpu_env.sh; export TORCH_EXTENSIONS_DIR=$PWD/build/torch_extensions
timeout 150 python3 scripts/kernel_times.py --data carry/data --scenes synthetic10M_4k --rows localgs,vanilla --iters 5 --top 30 2>&1 | grep -v "Warn\|warn(" > $out/kt_syn10m.log
grep "==" $out/kt_syn10m.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
