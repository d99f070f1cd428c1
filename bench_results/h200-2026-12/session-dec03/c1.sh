. scripts/gpu_env.sh
FWD_ROWS=localgs SCENE_TIMEOUT=100 bash scripts/scale_gpu_check.sh fwd > /dev/null 2>&1
XLA_FLAGS=--xla_gpu_enable_command_buffer= timeout 110 python3 -m benchmarks.scale --data carry/data --scenes guitar_x110_4k --rows localgs --repeat 10 2>&1 | grep -v arn > $out/cboff_fwd.log
grep -h " e2e " $out/fwd_*.log $out/cboff_fwd.log | cut -c1-240
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
