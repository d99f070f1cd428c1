# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call.
# carry/: data (guitar, lego_sh3, lego_train, skull), carry/wheels (gsplat 1.5.3 and
# pytest-timeout: scale_gpu_check.sh's tests then name a test that hangs in C and go on),
# and the earlier packages for in-process A/B (benchmarks/ab.py, new):
#   python -m benchmarks.ab prepare b2c9b27 ff6056a dad7a98 --to carry/old
# (b2c9b27: before this session's kernel changes; ff6056a: the reduction; dad7a98: exp2;
# HEAD adds walk_step's miss as α = 0).
# Before any call: `build/gpu-offline/bin/python scripts/gpu_build_offline.py` (14 built).
# 0. ff6056a (the backward's reduction: None term out, Scaled basis terms; pair step 220 -> 212
#    SASS instructions, 96 registers) has not run on a GPU. Its tests and the whole GPU set
#    (73 + 3 new CPU-side cases; about 3 min):
#      TEST_WORKERS=8 TEST_TIMEOUT=300 TEST_ARGS="\
#        tests/backends/test_backward_segments.py tests/backends/test_gaussian_grads.py \
#        tests/backends/test_gradients.py tests/backends/test_mosaic_staging.py \
#        tests/backends/test_pallas.py" bash scripts/scale_gpu_check.sh tests
#    then the A/B, all four packages in one process (about 3 min per scene):
#      python3 -m benchmarks.ab run synthetic4M_1080p --repeat 5 --against ff6056a
#        (bits: b2c9b27's rows equal ff6056a's expected: the reduction changes no bit)
#      python3 -m benchmarks.ab run guitar_x64_1080p --repeat 7
#        (bits: dad7a98's rows equal this tree's expected: walk_step; times: each change's
#        share, alternating rounds)
#      python3 -m benchmarks.ab run guitar_4k --fwd --repeat 9 (exp2 in the forward)
#    and the backward kernel's device time (4.06 ms at synthetic 4M this session):
#      python3 scripts/kernel_times.py --data carry/data --scenes synthetic4M_1080p --grad \
#        --rows localgs --iters 5 --top 8 (with gsplat: its 3.40 ms in the same process)
# 1. The issue tables again with gsplat in one process (Dec 3 sixth session's were before the
#    three cuts and the reduction): SCENES="synthetic4M_1080p synthetic10M_4k guitar_x110_4k"
#    bash scripts/scale_gpu_check.sh fwd, and ... grad (GRAD_ROWS=localgs,localgs@walked).
#    Expected from this session's A/B: synthetic 4M fwd+bwd about 0.99x gsplat (was 1.03x);
#    x110 4K forward about 0.83x (target 0.8x).
# 2. Skull training (TRAIN_SCENES=skull, 7k steps) against Dec 3's 15.16 / 11.35 ms, 26.81 dB.
# 3. gsplat's backward kernel under ncu: the wheel outside /tmp/site (pip --target /tmp/gs),
#      PYTHONPATH=$PWD:/tmp/gs ncu --clock-control none -k regex:3dgs_bwd -c 1 --set full \
#        python3 scripts/ncu_localgs.py carry/data --scene synthetic4M_1080p --backends pallas \
#        --kernel mosaic --grad --gsplat
# The commit after ff6056a computes α through exp2 (alpha.hoisted; SASS per pair: render
# forward 43.5 -> 40.25, backward 212 -> 204), also not yet run on a GPU: its check is step 0's
# test set (float32 tolerances against the float64 oracle and between the Mosaic GPU and Triton
# forwards; a forward and its backward are always one compiler's, Plan.for_gradients). Its
# time: the benchmarks.ab rows of dad7a98 and ff6056a above. 2f92278 (a miss as α = 0 in
# backward.walk_step: 204 -> 198) should leave the bits: dad7a98's rows "same bits" as HEAD.
