# call 6: forward against gsplat (issue 17's table)
. scripts/gpu_env.sh
SCENES="guitar_720p guitar_x16_1080p guitar_x110_4k" FWD_ROWS=localgs,vanilla bash scripts/scale_gpu_check.sh fwd > $out/fwd.txt 2>&1
tail -12 $out/fwd.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
