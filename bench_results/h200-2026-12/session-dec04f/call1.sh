# Call 1: Nsight Compute of one launch of the Local-GS and vanilla forward kernels at synthetic
# 4M, each in its own clean-environment process (last session's attempt segfaulted at ncu's
# start with gpu_env.sh's exports); then sh_sums' final form at SH degree 0 against 4ebdd1c.
base=${OUT:-out}; mkdir -p $base; t0=$(date +%s)
for b in pallas pallas_vanilla; do
  env -i PATH=$PATH HOME=$HOME PYTHONPATH=$PWD XLA_PYTHON_CLIENT_PREALLOCATE=false \
    timeout 200 ncu --clock-control none -k regex:'localgs_kernel|vanilla' -c 1 --set full \
    python3 scripts/ncu_localgs.py carry/data --scene synthetic4M_1080p --backends $b \
    --kernel mosaic > $base/ncu_fwd_syn4M_$b.txt 2>&1
  echo "ncu $b rc=$? $(( $(date +%s) - t0 )) s" >> $base/times.log
done
. scripts/gpu_env.sh
timeout 170 python3 -m benchmarks.ab run synthetic4M_1080p --old carry/old --revs 4ebdd1c \
  --repeat 7 --data carry/data > $base/ab_syn4M.txt 2>&1
echo "ab rc=$? $(( $(date +%s) - t0 )) s" >> $base/times.log
cat $base/times.log; tail -n 12 $base/ab_syn4M.txt
for b in pallas pallas_vanilla; do echo "== $b"
  grep -E "^  [a-z_]+.*\(|Duration|Registers Per|Achieved Occupancy|Executed Ipc A|Elapsed Cyc|Issue Slots Busy|No Eligible|Executed Instructions  " $base/ncu_fwd_syn4M_$b.txt | head -14; done
tar czf /tmp/all.tgz -C $base . && rm -rf $base/* && mv /tmp/all.tgz $base/
