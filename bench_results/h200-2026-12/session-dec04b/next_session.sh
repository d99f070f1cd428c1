# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call with
# carry ["carry"] (data, wheels, old/: lgs_5831554 for benchmarks.ab, tree_ff6056a for training).
# This session's kernel changes (built offline, never run on a GPU) are what to check first:
# 0b888c8/31b1b3b, the backward's pair step 206 -> 181 SASS instructions for the H200; and the
# compacted forward's record reads (43.5 -> 40.4 per pair, the same bits by construction).
#
# 1. The GPU tests of the backward, the quotient test first (its bits claim), then the in-process
#    A/B against the tree before the change (time ratio; the bits differ: the reduction's
#    multiply-adds; the quotients alone are bit-identical by the test):
#      TEST_WORKERS=8 TEST_TIMEOUT=300 TEST_ARGS="tests/backends/test_mosaic_quotients.py \
#        tests/backends/test_backward_segments.py tests/backends/test_gaussian_grads.py \
#        tests/backends/test_gradients.py tests/backends/test_mosaic_staging.py \
#        tests/backends/test_pallas.py" bash scripts/scale_gpu_check.sh tests
#      timeout 250 python3 -m benchmarks.ab run synthetic4M_1080p --old carry/old \
#        --revs 5831554 --repeat 5 --data carry/data
#    If test_quotients_are_the_kernels_division_to_the_bit fails: the rcp path is not div.full's
#    bits; revert mosaic_quotients (walk_step divides) and keep the multiply-adds.
# 2. Forward + backward against gsplat with walked rows, synthetic and captures (two calls):
#      SCENES="synthetic4M_1080p synthetic10M_4k guitar_x110_4k" GRAD_ROWS=localgs@walked \
#        SCENE_TIMEOUT=200 bash scripts/scale_gpu_check.sh grad
#      SCENES="guitar_720p guitar_4k lego_800 guitar_x16_1080p guitar_x64_1080p" \
#        GRAD_ROWS=localgs@walked bash scripts/scale_gpu_check.sh grad
#    (Dec 4, second session, before the change: synthetic 4M 8.21-8.26 ms against gsplat's 7.47
#    (1.10x), 10M 20.55-20.61 against 20.43 (1.01x); the offline count predicts about -0.45 ms
#    at 4M and -1.3 ms at 10M if the backward kernel's time follows its instructions. Memory
#    compiled offline with the four split entries: 10M 1675.6 MiB, 4M 642.3.)
# 3. Training after the change (the multiply-adds change the gradient's bits, so the
#    trajectories): skull 3k steps, seeds 0 and 1, and lego 3k at this tree and at
#    tree_ff6056a (its training bits are 5831554's: skull 25.07 / 26.14 dB at 3k, measured):
#      PYTHONPATH=TREE:/tmp/site python3 benchmarks/train_vs_gsplat.py --data-root carry/data \
#        --scenes skull --steps 3000 --eval-every 3000 --seed S --no-gsplat --out $OUT/x
#    (workers now import the tree on PYTHONPATH; summary.csv's `package` column says which).
# 4. The forward (issue 17) after the record reads: the A/B (bits must be equal to 5831554's:
#    the same rows are read) and the whole forward table against gsplat, with unroll 4 (now 84
#    registers: 6 blocks per SM, 44.25 instructions per pair) beside the default unroll 8:
#      timeout 200 python3 -m benchmarks.ab run synthetic4M_1080p --fwd --old carry/old \
#        --revs 5831554 --repeat 10 --data carry/data
#      timeout 440 python3 -m benchmarks.scale --data carry/data --csv $OUT/full.csv
#      python3 -m benchmarks.scale --no-gsplat --data carry/data --scenes synthetic4M_1080p \
#        guitar_x64_1080p --rows localgs,localgs:unroll4 --repeat 10
