# Next GPU session (after Dec 5's sixth session: BENCHMARKS.md §7 "Dec 5, sixth session"; the
# fifth session's call_four.sh ran here as call_one.sh and is removed). From the repository
# root, each call one `run`; carry only what it reads.
#
# Call 1 (carry carry/data/skull, carry/wheels): appearance embeddings over a longer run and on
# the scene-space relit capture at a GPU's size, beside plain runs:
#   . scripts/gpu_env.sh; export LGS_JAX_CACHE="$PWD/build/jax_cache"
#   timeout 300 python3 scripts/relit_capture.py --data carry/data --scene lego_train \
#     --truth lego_sh3/lego_sh3.ply --downscale 1 --steps 7000 --modes plain,app_opt
#   (carry carry/data/lego_train and lego_sh3's PLY: copy lego_sh3.ply alone into
#   carry/data/lego_sh3/, the folder is 17 MiB)
#
# Call 2: synthetic 4M's host share traced (session-dec05d/next_session.sh, call 2) and skull
# without streaming beside the fourth session's streamed runs (session-dec05d, call 1's last
# run).
#
# Call 3, on kind "nvidia-h200-x2" where lent: fit --devices 1 vs 2 (session-dec05b call 3).
