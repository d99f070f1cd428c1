# Next GPU session (after Dec 5's second session, which measured the Dec 4 seventh session's
# kernels, the antialiased mode and issue 17's table: BENCHMARKS.md §7 "Dec 5, second session").
# From the repository root, each call one `run`, carrying only what it reads, e.g.
# ["carry/data/skull", "carry/wheels", "carry/calls"] (carry/ whole is over the 64 MiB limit).
#
# Call 1 (about 6 min): streamed training views since a13af12 (a worker thread copies each view
# from its place in the capture; before it, streaming cost 7.5 ms per step on skull: 22.50
# against 14.96 ms). The three modes on one machine, the first run paying the compile:
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
for m in no-stream-images stream-images "stream-images --uint8-images" no-stream-images; do
  n=$(echo $m | tr -d ' -'); timeout 110 python3 -m lgs_jax fit --data carry/data/skull \
    --steps 3000 --eval-every 3000 --$m --out /tmp/s_$n > $out/fit_$n.log 2>&1
  echo "fit $m rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
  grep -E '"(ms_per_step|heldout_psnr|compile_seconds)"' $out/fit_$n.log >> $out/times.log
done
cat $out/times.log
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
# Expect the same held-out PSNR (21.660145565...) in all four, and the streamed ms per step
# within ~1 ms of the whole capture's. If not, profile one streamed step (jax.profiler).
#
# Call 2 (about 4 min): synthetic 4M's forward after the buckets default: device busy and the
# host's share (the 0.8x target's last 0.25 ms, BENCHMARKS §7 "Dec 5, second session"):
#   . scripts/gpu_env.sh; timeout 200 python3 scripts/kernel_times.py --data carry/data \
#     --scenes synthetic4M_1080p --rows localgs --iters 5 --top 30 --no-gsplat --host 40 \
#     > $out/kt_syn4M.log 2>&1; tail -n 40 $out/kt_syn4M.log
#
# Call 3, on kind "nvidia-h200-x2" (not lent on Dec 5; ask only with 10 min of budget left):
# data-parallel training, skull batch 2 on one and two GPUs (ms per step, held-out PSNR):
#   . scripts/gpu_env.sh; for n in 1 2; do timeout 190 python3 -m lgs_jax fit \
#     --data carry/data/skull --downscale 4 --steps 1500 --batch 2 --devices $n \
#     --eval-every 1500 --out /tmp/dp$n > $out/fit_dev$n.log 2>&1; \
#     grep -E '"(ms_per_step|heldout_psnr|compile_seconds)"' $out/fit_dev$n.log; done
