# call 1 (carry/ab_pkg.py = session-dec03e/ab_pkg.py): the kernels' GPU tests (backward reads five entry buffers), A/B vs cdc3380 at 0.09M 4K,
# then every kernel's time in forward + backward at 0.09M 4K, this tree and cdc3380's package
. scripts/gpu_env.sh
TEST_WORKERS=8 TEST_TIMEOUT=300 bash scripts/scale_gpu_check.sh tests > $out/tests_summary.txt 2>&1
timeout 90 python3 carry/ab_pkg.py guitar_4k 9 2>&1 | grep -v Warn > $out/ab_guitar_4k.log
timeout 80 python3 scripts/kernel_times.py --grad --data carry/data --scenes guitar_4k --rows localgs --iters 10 --top 40 --no-gsplat > $out/kt_head.log 2>&1
mkdir -p /tmp/oldtree && cp -r benchmarks scripts /tmp/oldtree/ && cp -r carry/old/lgs_old /tmp/oldtree/lgs_jax
grep -rl lgs_old /tmp/oldtree/lgs_jax | xargs sed -i 's/lgs_old/lgs_jax/g'
D=$PWD/carry/data; (cd /tmp/oldtree && PYTHONPATH=/tmp/site:/tmp/oldtree timeout 80 python3 scripts/kernel_times.py --grad --data $D --scenes guitar_4k --rows localgs --iters 10 --top 40 --no-gsplat) > $out/kt_old.log 2>&1
tail -3 $out/tests_summary.txt; grep "same bits\|rror" $out/ab*.log; grep -i "busy\|total" $out/kt_*.log | head
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
