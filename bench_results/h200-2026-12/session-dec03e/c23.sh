# call 3: which change costs forward time: HEAD vs 00ca7fa (table before binning) vs 387d23a, x110 fwd and x64 fwd;
# then every kernel's time at x110 4K forward, HEAD and 387d23a
. scripts/gpu_env.sh
timeout 120 python3 carry/ab3_pkg.py guitar_x110_4k 15 fwd 2>&1 | grep -v Warn > $out/ab3f_x110.log
timeout 90 python3 carry/ab3_pkg.py guitar_x64_1080p 15 fwd 2>&1 | grep -v Warn > $out/ab3f_x64.log
timeout 100 python3 scripts/kernel_times.py --data carry/data --scenes guitar_x110_4k --rows localgs --iters 5 --top 60 --no-gsplat > $out/kt_head.log 2>&1
mkdir -p /tmp/oldtree && cp -r benchmarks scripts /tmp/oldtree/ && cp -r carry/old/lgs_old /tmp/oldtree/lgs_jax
grep -rl lgs_old /tmp/oldtree/lgs_jax | xargs sed -i 's/lgs_old/lgs_jax/g'
D=$PWD/carry/data; (cd /tmp/oldtree && PYTHONPATH=/tmp/site:/tmp/oldtree timeout 100 python3 scripts/kernel_times.py --data $D --scenes guitar_x110_4k --rows localgs --iters 5 --top 60 --no-gsplat) > $out/kt_old.log 2>&1
grep "same bits\|rror" $out/ab3*.log; grep -i "busy" $out/kt_*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
