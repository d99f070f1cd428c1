# Next session, call 1 (next_session.sh step 0): skull 3k steps, seeds 0 and 1, at this tree
# and at ff6056a (before exp2), alternating, then lego 3k at both for the step time; no gsplat.
# Needs carry/old/tree_ff6056a (git archive ff6056a lgs_jax | tar -x -C carry/old/tree_ff6056a).
. scripts/gpu_env.sh
export LGS_JAX_CACHE="$PWD/build/jax_cache"
run() {  # tree scene seed
  local label; label=$([ "$1" = . ] && echo head || basename "$1"); local name="$2_${label}_$3"
  left=$((570 - SECONDS)); [ $left -lt 40 ] && return
  PYTHONPATH="$1:/tmp/site" python3 -P -c "import lgs_jax; print(lgs_jax.__file__)" >> $out/which.txt
  PYTHONPATH="$1:/tmp/site" timeout $left python3 benchmarks/train_vs_gsplat.py \
    --data-root carry/data --scenes $2 --steps 3000 --eval-every 3000 --seed $3 --no-gsplat \
    --out $out/$name --inline 2>&1 | tr '\r' '\n' | grep -v "step/s\|s/step" > $out/$name.log
  echo "$name: $(tail -n 1 $out/$name.log)" >> $out/summary.txt
}
PYTHONPATH="carry/old/tree_ff6056a:/tmp/site:$PWD" python3 -P -c "import lgs_jax; print(lgs_jax.__file__)" > $out/which.txt
for seed in 0 1; do run . skull $seed; run carry/old/tree_ff6056a skull $seed; done
run . lego 0; run carry/old/tree_ff6056a lego 0
cat $out/which.txt $out/summary.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
