# Call 5: a skull training step, da62541's tree against this one (call 4's 3k-step runs were
# 13.01 against 15.06 ms per step, both mostly steps beside compile-ahead threads): each
# piece of `train_step` timed alone (profile_train_step.py, 262k Gaussians in a 500k pool,
# SH degree 3), the old tree through a copy of the script beside its package.
. scripts/gpu_env.sh
base=$out; t0=$(date +%s)
for tree in head old; do
  dir=$PWD; [ $tree = head ] || dir=$PWD/carry/old/tree_da62541
  (cd $dir && timeout 130 python3 scripts/profile_train_step.py --data $OLDPWD/carry/data/skull \
    --no-gsplat --repeat 10) > $base/step_$tree.log 2>&1
  echo "$tree $(( $(date +%s) - t0 )) s" >> $base/times.log
done
cat $base/times.log; grep -v "^\s*$" $base/step_head.log | tail -14; grep -v "^\s*$" $base/step_old.log | tail -14
tar czf /tmp/all.tgz -C $base . && rm -rf $base/* && mv /tmp/all.tgz $base/
