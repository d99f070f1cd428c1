# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call.
# Set up carry/ as on Dec 3 (data: guitar, lego_sh3, lego_train, skull; the gsplat 1.5.3 wheel in
# carry/wheels).
# 0. Two changes of this session have not run on a GPU as a whole: the lean forward as the
#    default (mosaic_image_layout, mosaic_block_stops: only test_mosaic_staging's lean and
#    lowering tests ran, 6 passed, and lego training) and e20efcf (a loss without depth leaves
#    the depth's terms out of the backward's pair step: 240 -> 230 SASS instructions). First the
#    kernels' GPU tests: TEST_WORKERS=8 TEST_TIMEOUT=420 bash scripts/scale_gpu_check.sh tests
#    and (third change, the staged records one per row: vector loads, SASS per pair forward
#    53.9 -> 46.5 with 116 registers instead of 95, backward 230 -> 223) an in-process A/B
#    against the package at bdedc32 (before the last two; session-dec03e/ab_pkg.py with
#    carry/old/lgs_old made by `git archive bdedc32 lgs_jax` and a rename, as on Dec 3):
#      python3 carry/ab_pkg.py guitar_x64_1080p 7; ... guitar_x110_4k 5; ... synthetic4M_1080p 5
#      python3 carry/ab_pkg.py guitar_4k 9 fwd
#    and the forward's unroll (render forward 116 vs 95 registers):
#      SCENES="guitar_720p guitar_x16_1080p guitar_x64_1080p guitar_x110_4k" \
#        FWD_ROWS=localgs,localgs:unroll4,vanilla bash scripts/scale_gpu_check.sh fwd
#    then the kernels' time at synthetic 4M / 10M against this session's backward 4.33 / 11.68
#    ms and forward 1.38 / 3.95 (3_train_kt/): SCENES="synthetic4M_1080p synthetic10M_4k"
#    KT_ARGS="--grad --rows localgs --iters 5 --top 8" bash scripts/scale_gpu_check.sh kernels,
#    then skull training (TRAIN_SCENES=skull, 7k steps) against Dec 3's 15.16 / 11.35 ms,
#    26.81 dB.
# 1. gsplat's backward kernel under Nsight Compute beside ours (ours: 4_ncu/ncu_bwd_syn4M.txt,
#    issue-bound, 3.67 G instructions). ncu segfaulted at start whenever /tmp/site (the gsplat
#    wheel) was on PYTHONPATH: install the wheel elsewhere (pip --target /tmp/gs, or `pip install`
#    into the user site) and retry:
#      PYTHONPATH=$PWD:/tmp/gs ncu --clock-control none -k regex:3dgs_bwd -c 1 --set full \
#        python3 scripts/ncu_localgs.py carry/data --scene synthetic4M_1080p --backends pallas \
#        --kernel mosaic --grad --gsplat
#    Compare instructions per walked pair and the pipe mix with ours; `--set full` with
#    `--import-source yes` and `-k regex:localgs_backward` for the source-level hot spots
#    (SASS: which instructions the butterfly's selects and the α arithmetic cost).
# 2. The 4K forward's host share (issue 17's 0.8x at x110, 0.88x now): session-dec03d/cb_probe.py
#    with more variants, e.g. {"xla_gpu_graph_min_graph_size": 1}; `python3 cb_probe.py
#    guitar_x110_4k 20`.
# 3. Offline first (no GPU needed): `build/gpu-offline/bin/python scripts/kernel_sass.py
#    guitar_720p [--grad]` gives every Mosaic GPU kernel's SASS per pair. Open items it measured:
#    α through exp2 (ex2.approx; forward 43.5 -> 40.25 per pair) once it is checked on the GPU
#    that every forward/backward pairing (Mosaic GPU with Triton, auto_backward="triton")
#    computes α to the same bits; the backward's reduction (72 of its 220 instructions per pair).
