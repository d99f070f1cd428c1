# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call.
# Set up carry/ as on Dec 3 (data: guitar, lego_sh3, lego_train, skull; the gsplat 1.5.3 wheel in
# carry/wheels).
# 0. Two changes of this session have not run on a GPU as a whole: the lean forward as the
#    default (mosaic_image_layout, mosaic_block_stops: only test_mosaic_staging's lean and
#    lowering tests ran, 6 passed, and lego training) and e20efcf (a loss without depth leaves
#    the depth's terms out of the backward's pair step: 240 -> 230 SASS instructions). First the
#    kernels' GPU tests: TEST_WORKERS=8 TEST_TIMEOUT=420 bash scripts/scale_gpu_check.sh tests
#    then the backward kernel's time at synthetic 4M / 10M against this session's 4.33 / 11.68 ms
#    (3_train_kt/): SCENES="synthetic4M_1080p synthetic10M_4k" KT_ARGS="--grad --rows localgs
#    --iters 5 --top 8" bash scripts/scale_gpu_check.sh kernels (expected about 4% less), then
#    skull training (TRAIN_SCENES=skull, 7k steps) against Dec 3's 15.16 / 11.35 ms, 26.81 dB.
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
