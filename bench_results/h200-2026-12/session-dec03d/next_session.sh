# Next GPU session (issues 17 and 18), from the repository root; each step one `run` call.
# Set up carry/ as on Dec 3 (data, gsplat wheel), plus:
#   carry/ab_pkg.py = this folder's ab_pkg.py; carry/old/lgs_old = `git archive 387d23a lgs_jax`
#   renamed lgs_old (387d23a: whole-tile backward blocks, before this session's two memory
#   changes: the table before binning, the 13-column table).
# 0. The kernels changed (the table's 13 columns are staged by the Mosaic GPU kernels): their
#    GPU tests first, then the A/B in one process (time, memory, same bits), forward and grad:
#      bash scripts/scale_gpu_check.sh tests
#      for s in guitar_x16_1080p guitar_x64_1080p guitar_x110_4k; do
#        timeout 150 python3 carry/ab_pkg.py $s 7; timeout 100 python3 carry/ab_pkg.py $s 10 fwd; done
#    Expected (scripts/gpu_memory_offline.py): walked rows x110 1616 -> 1578 MiB, x64 930 ->
#    842, x16 283 -> 278; x110 forward 1297 -> 1230; times within ~0.1 ms (the ellipse is
#    computed twice now). Revert whichever change costs more time than it is worth.
# 1. Against gsplat (the issue tables):
#      SCENES="guitar_x16_1080p guitar_x64_1080p guitar_x110_4k" SCENE_TIMEOUT=110 \
#        bash scripts/scale_gpu_check.sh grad
#      SCENES="guitar_720p guitar_x16_1080p guitar_x110_4k" FWD_ROWS=localgs bash scripts/scale_gpu_check.sh fwd
# 2. Training unchanged? TRAIN_SCENES=lego bash scripts/scale_gpu_check.sh train
