# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call.
# Set up carry/ as on Dec 3 (data: guitar, lego_sh3, lego_train, skull; the gsplat 1.5.3 wheel in
# carry/wheels). Nothing in the package changed this session, so no A/B is needed first.
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
