# call 5: forward+backward vs gsplat at 1080p with whole-tile backward blocks (the new default);
# the 4K x110 walked gradient's peak (XLA dump, hlo_peak)
. scripts/gpu_env.sh
SCENES="guitar_x16_1080p guitar_x64_1080p" SCENE_TIMEOUT=110 bash scripts/scale_gpu_check.sh grad > $out/grad.txt 2>&1
mkdir -p /tmp/dump
XLA_FLAGS="--xla_dump_to=/tmp/dump --xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*loss.*" timeout 100 \
  python3 -m benchmarks.scale --grad --no-gsplat --data carry/data --scenes guitar_x110_4k --rows localgs@walked --repeat 1 2>&1 | grep "grad:" > $out/dump_run.log
p=$(ls /tmp/dump/module_*after_optimizations-buffer-assignment.txt | head -1); p=${p%-buffer-assignment.txt}
python3 scripts/hlo_peak.py $p --top 30 > $out/peak_x110.txt 2>&1
cat $out/grad.txt | tail -6; cat $out/dump_run.log; head -45 $out/peak_x110.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
