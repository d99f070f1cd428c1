# Dec 4, second session, call 3: exp2 reverted in alpha.hoisted (this tree). Skull 3k steps seed 0
# at this tree (ff6056a gave 25.07 dB, HEAD with exp2 24.12: the same number means exp2 was the
# whole difference and 2f92278 / the 44-byte rows kept the training's bits), then the 10M/4K
# gradient's memory with the 44-byte rows on the GPU, then skull seed 1 (ff6056a 26.14) if time.
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
train() {  # seed
  left=$((520 - SECONDS)); [ $left -lt 60 ] && return
  PYTHONPATH=".:/tmp/site" timeout $left python3 benchmarks/train_vs_gsplat.py \
    --data-root carry/data --scenes skull --steps 3000 --eval-every 3000 --seed $1 --no-gsplat \
    --out $out/skull_revexp2_$1 --inline 2>&1 | tr '\r' '\n' | grep -v "step/s\|s/step" \
    > $out/skull_revexp2_$1.log
  echo "skull_revexp2_$1: $(tail -n 1 $out/skull_revexp2_$1.log)" >> $out/summary.txt
}
train 0
OUT=$out/grad10M SCENES="synthetic10M_4k" GRAD_ROWS=localgs@walked SCENE_TIMEOUT=200 \
  timeout $((500 - SECONDS)) bash scripts/scale_gpu_check.sh grad > $out/grad10M.log 2>&1
train 1
tail -n 12 $out/grad10M.log; cat $out/summary.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
