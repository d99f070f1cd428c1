# Call 2: the colour-features render on the GPU (its tests and its cost per pass), the
# camera-gradient fix's GPU check, and synthetic 4M's host share after the buckets default.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > $out/device.txt
timeout 200 python3 -m pytest -q -p no:cacheprovider -n 8 tests/test_colors.py \
  tests/backends/test_gradients.py tests/train/test_camera_opt.py > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; tail -n 4 $out/tests.log
timeout 120 python3 -m benchmarks.features --data carry/data --scene guitar@1920x1080 \
  --scene guitar_x16_1080p --channels 1,3,8,16,32 --repeat 10 > $out/features.log 2>&1
echo "features rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; cat $out/features.log
timeout 150 python3 scripts/kernel_times.py --data carry/data --scenes synthetic4M_1080p \
  --rows localgs --iters 5 --top 30 --no-gsplat --host 40 > $out/kt_syn4M.log 2>&1
echo "kernel_times rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
tail -n 40 $out/kt_syn4M.log | cut -c1-200; cat $out/device.txt $out/times.log
