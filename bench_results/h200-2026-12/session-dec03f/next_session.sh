# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call.
# Set up carry/ as on Dec 3 (data: guitar, lego_sh3, lego_train, skull; the gsplat 1.5.3 wheel in
# carry/wheels).
# 0. KernelConfig.mosaic_image_layout and mosaic_block_stops (built this session, off by
#    default; never run on a GPU): their tests compiled (the slow gradient case too), then time
#    and memory against the planes in one process per scene, forward and forward + backward:
#      TEST_ARGS="tests/backends/test_mosaic_staging.py -k 'lean or lowers'" \
#        bash scripts/scale_gpu_check.sh tests
#      SCENES="guitar_720p lego_800 guitar_4k guitar_x110_4k" \
#        FWD_ROWS=localgs,localgs:image,localgs:lean bash scripts/scale_gpu_check.sh fwd
#      SCENES="guitar_4k guitar_x16_1080p" GRAD_ROWS=localgs@walked,localgs:lean@walked \
#        bash scripts/scale_gpu_check.sh grad
#    Expected memory (offline): forward 720p 32.9 -> 26.9 (image) -> 23.4 MiB (lean), lego
#    23 -> 18.7 -> 16.2, 4K 263.5 -> 200.2 -> 168.8; gradients unchanged with walked rows. If
#    the images are the planes' (bit for bit in float32) and the time holds: both on by
#    default, the gradient test out of `slow` and ~50 s of CI taken out elsewhere.
# 1. Training unchanged since the split backward's entries (not run since Dec 2):
#      TRAIN_SCENES=lego bash scripts/scale_gpu_check.sh train
# 2. The synthetic scenes miss both issues (forward 0.93x / 1.05x, fwd+bwd 1.03x / 1.07x, memory
#    with walked rows 1.06x). Every kernel of their forward + backward, ours and gsplat's:
#      SCENES="synthetic10M_4k synthetic4M_1080p" KT_ARGS="--grad --rows localgs --iters 5 \
#        --top 40" bash scripts/scale_gpu_check.sh kernels
#    and the walked pairs there (the row buffer's slack under pair_capacity's grid; rows 10.49M
#    and 3.67M were used): `benchmarks.scale --grad` prints them beside the rows now, e.g.
#      SCENES="synthetic4M_1080p synthetic10M_4k" GRAD_ROWS=localgs@walked \
#        bash scripts/scale_gpu_check.sh grad
# 3. The 4K forward's host share (issue 17's 0.8x at x110, 0.90x now): session-dec03d/cb_probe.py
#    with more variants, e.g. {"xla_gpu_graph_min_graph_size": 1}, and the command buffer types
#    listed explicitly with custom calls; `python3 cb_probe.py guitar_x110_4k 20`.
