# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call with
# carry ["carry"] (data: guitar, lego_sh3, skull, lego_train; wheels: gsplat 1.5.3,
# pytest-timeout; old/: `python -m benchmarks.ab prepare da62541 --to carry/old`, the tree
# before the SH cotangents left the barrier). Built offline and never run on a GPU: 602cc56,
# `projection.gaussian_columns`' vjp without the SH cotangents behind its barrier, and d8be94b,
# the pallas backward's cotangent planes made after the row layout (a select
# on an always-true predicate): compiled for the H200, lego x16 1080p forward + backward
# (walked rows) 494.4 -> 353.1 -> 327.6 MiB (gsplat 346).
#
# 1. GPU tests of the projection and gradients, then the A/B at lego x16 (SH degree 3): memory
#    must be 328 MiB; the means', rotations', scales' and opacities' gradient bits equal
#    da62541's, ∂L/∂sh within float32 rounding (another fusion computes the products); time
#    lower or equal (176 MiB less written and read):
#      TEST_WORKERS=8 TEST_TIMEOUT=260 TEST_ARGS="tests/test_projection.py \
#        tests/backends/test_gradients.py tests/backends/test_gaussian_grads.py \
#        tests/backends/test_backward_segments.py tests/backends/test_pallas.py tests/train" \
#        bash scripts/scale_gpu_check.sh tests
#      timeout 150 python3 -m benchmarks.ab run lego_x16_1080p --old carry/old \
#        --revs da62541 --repeat 5 --data carry/data
#    (benchmarks.ab compares every gradient's bits; if only d_sh differs, that is expected.)
# 2. The small scenes and lego x16 against gsplat, walked rows (issue 18's table at one tree):
#      SCENES="lego_x16_1080p lego_800 guitar_720p guitar_4k" GRAD_ROWS=localgs@walked \
#        SCENE_TIMEOUT=100 bash scripts/scale_gpu_check.sh grad
# 3. Skull training before and after in one call (peak memory should fall by up to 192 bytes
#    per pooled Gaussian; ms per step equal or lower), the old tree through PYTHONPATH:
#      for tree in head old; do pp=$PYTHONPATH; [ $tree = head ] || pp="$PWD/carry/old/tree_da62541:$pp"
#        PYTHONPATH=$pp timeout 250 python3 benchmarks/train_vs_gsplat.py --data-root carry/data \
#          --scenes skull --steps 3000 --eval-every 3000 --no-gsplat --out $OUT/skull_$tree; done
#    (train_vs_gsplat imports lgs_jax, so the old tree is a plain one: `git archive da62541
#    lgs_jax | tar x -C carry/old/tree_da62541`; benchmarks.ab's package is lgs_da62541.)
# 4. Where the forward kernel's time goes at the uniform scenes (issue 17's three misses: the
#    device is 2.20 ms of the 2.68 ms blocked call at synthetic 4M, the Local-GS kernel 1.02 of
#    it; its 116 registers allow 4 blocks per SM): Nsight Compute on one launch of ours and of
#    gsplat's forward rasterizer, full set (stall reasons: does the chunk staging's dependent id
#    -> row loads show as long-scoreboard stalls, or the blend loop's issue rate?):
#      timeout 200 python3 -c "from gsplat.cuda._backend import _C"
#      timeout 330 ncu --clock-control none -k regex:'localgs_kernel|rasterize_to_pixels' -c 2 \
#        --set full python3 scripts/ncu_localgs.py carry/data --scene synthetic4M_1080p \
#        --backends pallas --kernel mosaic --gsplat > $OUT/ncu_fwd_syn4M.txt
#    then grep "Duration|Registers Per|Achieved Occupancy|Executed Ipc A|Stall|No Eligible".
