# Next GPU session (issue 18's memory): measure sums_in_place.patch, with gsplat in the same
# process this time. From the repository root, after `git apply` of the patch:
#   run 1: bash scripts/scale_gpu_check.sh tests   (TEST_ARGS="tests/backends/test_gaussian_grads.py
#          tests/backends/test_backward_segments.py tests/backends/test_gradients.py")
#   run 2: SCENES="guitar_x16_1080p guitar_x64_1080p guitar_x110_4k" SCENE_TIMEOUT=110 \
#          bash scripts/scale_gpu_check.sh grad
# Expected at x110 with walked rows: about 1568 MiB (0.98x gsplat's 1600) if the
# compaction's step (1034 MiB of temporaries) becomes the peak; check with
#   XLA_FLAGS="--xla_dump_to=/tmp/hlo --xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*jit_loss.*"
#   python -m benchmarks.scale --grad --no-gsplat --data carry/data --scenes guitar_x110_4k \
#     --rows localgs@walked && python scripts/hlo_peak.py /tmp/hlo/<module> --temp
