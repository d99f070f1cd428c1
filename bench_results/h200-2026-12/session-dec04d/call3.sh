# Call 3: the forward table, all nine scenes, after the 10-column table.
. scripts/gpu_env.sh
t0=$(date +%s)
timeout 540 python3 -m benchmarks.scale --data carry/data --csv $out/full.csv > $out/full.log 2>&1
echo "full $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/times.log; grep -v "Warn\|warn" $out/full.log | tail -40
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
