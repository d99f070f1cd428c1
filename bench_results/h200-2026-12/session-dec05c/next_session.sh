# Next GPU session (after Dec 5's third session, which had no GPU: BENCHMARKS.md §7 "Dec 5,
# third session"). The calls of session-dec05b/next_session.sh still stand (threaded
# streaming, synthetic 4M's host share, two GPUs); call 1 below replaces its call 1 and adds
# this session's bilateral grids. From the repository root, each call one `run`, carrying only
# what it reads, e.g. ["carry/data/skull", "carry/wheels", "carry/calls"].
#
# Call 1 (about 7 min): skull 3k steps in four modes on one machine, the first paying the
# compile; the grid's cost per step (its slice and gradient: dense contractions over 8 row
# blocks, about 3 GFLOP a step at 1063x708 with the backward) and its held-out score:
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
for m in no-stream-images stream-images "stream-images --uint8-images" \
         "no-stream-images --bilateral-grid"; do
  n=$(echo $m | tr -d ' -'); timeout 120 python3 -m lgs_jax fit --data carry/data/skull \
    --steps 3000 --eval-every 3000 --$m --out /tmp/s_$n > $out/fit_$n.log 2>&1
  echo "fit $m rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
  grep -E '"(ms_per_step|heldout_psnr|compile_seconds)"' $out/fit_$n.log >> $out/times.log
done
cat $out/times.log
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
# Expect the same held-out PSNR (21.660145565...) in the first three, the streamed ms per step
# within ~1 ms of the whole capture's, and the grid's within ~1.5 ms of the first (if more,
# time `bilateral_grid.corrected` alone at 1063x708 and try 4 or 16 row blocks).
