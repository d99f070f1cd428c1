# call 4: 13 columns with and without the table before binning (lgs_v = HEAD with Backend.gaussian_table None)
. scripts/gpu_env.sh
P=lgs_jax,lgs_v,lgs_old
timeout 110 python3 carry/abn.py guitar_x110_4k 15 fwd $P 2>&1 | grep -v Warn > $out/fwd_x110.log
timeout 80 python3 carry/abn.py guitar_x64_1080p 15 fwd $P 2>&1 | grep -v Warn > $out/fwd_x64.log
timeout 130 python3 carry/abn.py guitar_x110_4k 9 walked $P 2>&1 | grep -v Warn > $out/walked_x110.log
timeout 100 python3 carry/abn.py guitar_x64_1080p 9 walked $P 2>&1 | grep -v Warn > $out/walked_x64.log
grep -h "same bits\|rror" $out/*.log
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
