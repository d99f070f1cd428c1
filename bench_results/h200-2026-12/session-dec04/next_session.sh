# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call.
# carry/: data (guitar, lego_sh3, lego_train, skull), wheels (gsplat 1.5.3, pytest-timeout),
# old/ (benchmarks.ab packages). Before any call that changes a kernel:
#   build/gpu-offline/bin/python scripts/gpu_build_offline.py   (14 built)
# 0. (ready: session-dec04/next_c1.sh; carry/old/tree_ff6056a is prepared.) Skull's held-out
#    PSNR moved 26.81 -> 25.51 dB with exp2 (dad7a98) and lego's step took 9.33 ms against 7.26 on a machine whose compiles were 13-30% slower. Both trees in one call:
#      git archive ff6056a lgs_jax | tar -x -C carry/old/tree_ff6056a   (package not renamed)
#    then, per tree in ". carry/old/tree_ff6056a" and seed in 0 1 (3k steps, about 100 s each):
#      PYTHONPATH=$tree:/tmp/site:$PWD python3 benchmarks/train_vs_gsplat.py --data-root \
#        carry/data --scenes skull --steps 3000 --eval-every 3000 --seed $seed --no-gsplat \
#        --out $OUT/skull_$(basename $tree)_$seed
#    (python3 -c "import lgs_jax; print(lgs_jax.__file__)" under each PYTHONPATH first). A
#    systematic loss would be every seed lower at this tree; then revert exp2 (alpha.hoisted).
#    And lego at both trees, alternating, for the step time (host-bound at 200x200).
# 1. The 10M/4K gradient with the 44-byte rows on the GPU (offline: 1685.6 MiB, 1.04x):
#      SCENES="synthetic10M_4k guitar_x110_4k" GRAD_ROWS=localgs@walked SCENE_TIMEOUT=200 \
#        bash scripts/scale_gpu_check.sh grad
# 2. Whether 2f92278 (a miss as α = 0) kept dad7a98's bits (cut by the time limit twice):
#      python3 -m benchmarks.ab run synthetic4M_1080p --revs dad7a98 --against dad7a98 --repeat 3
# 3. The captures' forward + backward against gsplat (last measured Dec 3, sixth session):
#      SCENES="guitar_720p guitar_4k lego_800 guitar_x16_1080p guitar_x64_1080p" \
#        bash scripts/scale_gpu_check.sh grad
