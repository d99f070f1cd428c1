# call 4: Nsight Compute on the two backward kernels at synthetic 4M / 1080p (ours 4.33 ms
# against gsplat's 3.40 in call 3): one launch of each, full set, clocks left alone
. scripts/gpu_env.sh
timeout 200 python3 -c "from gsplat.cuda._backend import _C; assert _C is not None" 2>&1 | grep "set up\|rror"
timeout 330 ncu --clock-control none -k regex:'localgs_backward|3dgs_bwd' -c 2 --set full \
  python3 scripts/ncu_localgs.py carry/data --scene synthetic4M_1080p --backends pallas \
  --kernel mosaic --grad --gsplat > $out/ncu_bwd_synthetic4M.txt 2> $out/ncu_err.txt
echo rc $?; tail -3 $out/ncu_err.txt
grep -E "^  [a-z].*\(|Duration|Registers Per|Achieved Occupancy|Theoretical Occupancy|Executed Ipc A|Memory Throughput|Compute \(SM\) Throughput|Block Size|Grid Size|No Eligible|Issued Warp|Dynamic Shared" $out/ncu_bwd_synthetic4M.txt | head -40
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
