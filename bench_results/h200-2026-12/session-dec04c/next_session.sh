# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call with
# carry ["carry"] (data, wheels, old/: lgs_786c63c = the tree before the 10-column table,
# lgs_5831554, lgs_687481c). Built offline and never run on a GPU: 6848b3a, the Gaussian table
# in 10 columns (the strip masks' padded ellipse computed in the kernels' staging): compiled
# for the H200, synthetic 10M/4K forward + backward 1675.6 -> 1561.1 MiB, 4M 642.3 -> 596.5.
#
# 1. The GPU tests of the staging, masks and gradients (the in-kernel ellipse), then the A/Bs
#    against 786c63c: the images and gradients must equal its bits (masks only cull pairs
#    whose alpha is below 1/255 on the whole strip), the time within about 1%, memory lower:
#      TEST_WORKERS=8 TEST_TIMEOUT=260 TEST_ARGS="tests/test_pairs.py \
#        tests/backends/test_mosaic_staging.py tests/backends/test_table_kernel.py \
#        tests/backends/test_pallas.py tests/backends/test_backward_segments.py \
#        tests/backends/test_gradients.py" bash scripts/scale_gpu_check.sh tests
#      timeout 150 python3 -m benchmarks.ab run synthetic4M_1080p --old carry/old \
#        --revs 786c63c --repeat 5 --data carry/data
#      timeout 120 python3 -m benchmarks.ab run synthetic10M_4k --fwd --old carry/old \
#        --revs 786c63c --repeat 5 --data carry/data
#    If the bits differ: a mask dropped a pair that contributes (the ellipse's bound broke
#    under the kernel's arithmetic); compare `pairs.strip_masks` (XLA) with the kernel's on the
#    failing scene before anything else.
# 2. Forward + backward against gsplat, walked rows (memory measured: expect 597 / 1561 MiB):
#      SCENES="synthetic4M_1080p synthetic10M_4k guitar_x110_4k" GRAD_ROWS=localgs@walked \
#        SCENE_TIMEOUT=200 bash scripts/scale_gpu_check.sh grad
# 3. The forward table (all nine scenes; this session's lego rows were out of line with their
#    A/B: 1.88 vs 1.45 ms at lego x16, 0.75 vs 0.41 at lego 800 — rerun and compare):
#      timeout 480 python3 -m benchmarks.scale --data carry/data --csv $OUT/full.csv
