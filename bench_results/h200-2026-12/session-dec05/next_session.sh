# Next GPU session (the Dec 4 seventh and Dec 5 sessions got no GPU machine: fdfa05f, 93a8194 and
# 4e2830a are built and compiled for the H200 offline only; BENCHMARKS.md §7 "Dec 4, seventh
# session"; Dec 5 added the antialiased mode, checked against gsplat's below). From the
# repository root, each call one `run` with carry ["carry"] (carry/old holds lgs_06294ad, the
# tree before them: `python3 -m benchmarks.ab prepare 06294ad --to carry/old` if missing).
#
# Call 1 (about 8 min): the changed kernels on the GPU, then their bits and time against
# 06294ad in one process. If a test hangs or fails, or an "equal" column says no, find which
# of this session's kernel commits did it (fdfa05f: the loop's bar.red, the stop pair as the
# done flag, the per-warp lists' skipped mask test; 93a8194: the bar.red's layout; the
# sentinel commit after them: no per-pair count test) and revert it before anything else.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
timeout 330 python3 -m pytest -q -p no:cacheprovider -n 8 -m 'slow or not slow' -rf \
  --tb=short tests/backends/test_backward_segments.py tests/backends/test_gradients.py \
  tests/backends/test_mosaic_staging.py tests/backends/test_pallas.py \
  tests/backends/test_mosaic_inline.py > $out/tests.log 2>&1
echo "tests rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
for s in synthetic10M_4k guitar_x16_1080p; do
  timeout 90 python3 -m benchmarks.ab run $s --old carry/old --revs 06294ad --fwd --repeat 10 \
    --data carry/data > $out/ab_fwd_$s.log 2>&1
  echo "ab fwd $s rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
done
timeout 100 python3 -m benchmarks.ab run synthetic4M_1080p --old carry/old --revs 06294ad \
  --repeat 5 --data carry/data > $out/ab_grad_syn4M.log 2>&1
echo "ab grad rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/times.log; grep "^FAILED\|passed\|failed" $out/tests.log | tail -5
tail -n 6 $out/ab_*.log | cut -c1-150
# RasterConfig(antialiased=True) against gsplat's rasterize_mode="antialiased" (Dec 5; only the
# float64 oracle checked it on a CPU): expect 100+ dB as the classic mode's, both scenes.
timeout 120 python3 -m benchmarks.render_vs_gsplat --data carry/data --scene guitar@1280x720 \
  --scene lego_sh3@800x800 --rows pallas --repeat 5 --antialiased > $out/antialiased.log 2>&1
echo "antialiased rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log; tail -n 2 $out/antialiased.log
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
#
# Call 2 (about 8 min): issue 17's table where it is closest to its targets, 20 rounds (the
# scenes of >= 5M Gaussians too: `--big-repeat 20`; the Dec 4 sixth session's "20 rounds"
# table ran those at benchmarks.scale's default of 7), gsplat
# in the process; the vanilla kernel's row gives the Local-GS lead (both kernels changed);
# `localgs:buckets` the blocks' order without the CUB sort of 32,400 tiles at 4K
# (KernelConfig.block_order, built this session: one CUB launch fewer, host time per call):
# if its e2e is lower at both 4K scenes, make "buckets" the default, then the gradient
# (`--grad --rows localgs@walked,localgs:buckets@walked`: the split backward's segments too).
#   . scripts/gpu_env.sh; for s in synthetic10M_4k guitar_x110_4k synthetic4M_1080p; do
#     timeout 160 python3 -m benchmarks.scale --data carry/data --scenes $s \
#       --rows localgs,localgs:buckets,vanilla --repeat 20 --big-repeat 20 --csv $out/fwd_$s.csv \
#       > $out/fwd_$s.log 2>&1; done
#
# Call 3 (about 8 min): the forward's host share at synthetic 10M, then skull's 7k steps with
# this session's kernels (the gradient's forward runs the compacted walk):
#   . scripts/gpu_env.sh; timeout 200 python3 scripts/kernel_times.py --data carry/data \
#     --scenes synthetic10M_4k --host 40 > $out/kt_syn10M.log 2>&1
#   TRAIN_SCENES=skull bash scripts/scale_gpu_check.sh train
# (Dec 5: train_step now takes the step's images gathered before it, `data.TrainViews`: compare
# its ms per step with 10.6-12.0 before; then the cost of streaming them from the host:)
#   for m in no-stream-images stream-images uint8-images; do timeout 200 python3 -m lgs_jax fit \
#     --data carry/data/skull --steps 3000 --eval-every 3000 --$m --out /tmp/s_$m \
#     2>/dev/null | grep -E "ms_per_step|heldout_psnr"; done
# (and, if the call has time, pose optimization's held-out PSNR and step cost on the skull:)
#   timeout 200 python3 -m lgs_jax fit --data carry/data/skull --steps 3000 --eval-every 3000 \
#     --pose-opt --out /tmp/s_pose 2>/dev/null | grep -E "ms_per_step|heldout_psnr"
#
# Call 4, on kind "nvidia-h200-x2" (two GPUs; ask only if the budget has 10 min left): the
# data-parallel step (fit --devices, built this session on two CPU devices only). The same
# skull run, batch 2, on one and on two GPUs: ms per step and held-out PSNR (the runs follow
# each other to float rounding, so the PSNR should agree within the seeds' spread):
#   . scripts/gpu_env.sh; for n in 1 2; do timeout 270 python3 -m lgs_jax fit \
#     --data carry/data/skull --downscale 4 --steps 1500 --batch 2 --devices $n \
#     --eval-every 1500 --out /tmp/dp$n > $out/fit_dev$n.log 2>&1; \
#     tail -n 20 $out/fit_dev$n.log | grep -E "ms_per_step|heldout_psnr|compile_seconds"; done
