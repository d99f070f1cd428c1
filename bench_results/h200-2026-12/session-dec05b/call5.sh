. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
timeout 130 python3 -m lgs_jax fit --data carry/data/skull --steps 3000 --eval-every 3000 \
  --no-stream-images --out /tmp/s_ns > $out/fit_no-stream-images.log 2>&1
echo "fit no-stream rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
TRAIN_SCENES=skull timeout 330 bash scripts/scale_gpu_check.sh train > $out/train.log 2>&1
echo "train rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
cat $out/times.log
for f in $out/fit_*.log; do echo "== $f"; grep -E "ms_per_step|heldout_psnr|compile_sec|rror" $f | tail -n 4 | cut -c1-200; done
tail -n 12 $out/train.log | cut -c1-200
tar czf /tmp/all.tgz -C $out . && rm -rf $out/* && mv /tmp/all.tgz $out/
