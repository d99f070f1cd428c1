#!/usr/bin/env bash
# Scale GPU session (issues 17 and 18), one device call per part, each under 10 minutes:
#   bash scripts/scale_gpu_check.sh tests  # the split backward's, walked rows' and staging
#                                          # (compaction included) tests (about 6 min:
#                                          # TEST_WORKERS=8 TEST_TIMEOUT=420; TEST_ARGS
#                                          # replaces the files, e.g. "FILE -k NAME")
#   bash scripts/scale_gpu_check.sh grad   # forward + backward per scene (about 6 min)
#   bash scripts/scale_gpu_check.sh fwd    # forward per scene
#   bash scripts/scale_gpu_check.sh kernels  # every kernel's device time in one forward, ours
#                                          # and gsplat's (scripts/kernel_times.py; SCENES
#                                          # default guitar_x110_4k, KT_ARGS e.g. --grad)
#   bash scripts/scale_gpu_check.sh train  # skull, 7k steps, ms per step (no gsplat; 5 min;
#                                          # TRAIN_ARGS=--compile-ahead-process, --no-compile-ahead,
#                                          # --pair-headroom 3; TRAIN_SCENES=lego)
#   bash scripts/scale_gpu_check.sh ahead  # steps beside a compile ahead (ahead_contention.py)
#   bash scripts/scale_gpu_check.sh compact  # KernelConfig.mosaic_compact on the GPU: its tests,
#                                          # then forward and forward + backward against the
#                                          # full walks per scene, no gsplat (about 6 min)
#   bash scripts/scale_gpu_check.sh determinism  # skull, 1500 steps (two growths) without
#                                          # compile ahead twice and with a thread, each compiling
#                                          # afresh: the checkpoints' digests (about 6 min; DET_RUNS
#                                          # adds e.g. process:--compile-ahead-process)
# Dec 2 (H200): gsplat's build took 107 s, then `grad` with two rows about 65 s per scene, and
# `train` 287 s. Lines are written as they come, so a call cut by its time limit keeps them.
# One benchmarks.scale process per scene (a failing row costs one scene, not the run), gsplat
# 1.5.3 in the same process. Run from the repository root on the device machine (scenes in
# carry/data, the gsplat wheel in carry/wheels); logs and CSVs to $OUT; a short table last.
set -uo pipefail
. "$(dirname "$0")/gpu_env.sh"
export LGS_JAX_CACHE="$PWD/build/jax_cache"
quiet() { grep --line-buffered -v "Warning\|warn(\|t = lambda"; }
# Build gsplat's extension once, before any timed process: a build killed by a scene's timeout
# leaves torch's lock file behind and every later import waits on it forever.
build_gsplat() {
  timeout 240 python3 -c "from gsplat.cuda._backend import _C; assert _C is not None" 2>&1 \
    | grep --line-buffered "set up\|rror" | tee "$out/gsplat_build.log"
}
# A switch's GPU check: its tests (pytest arguments $2), then benchmarks.scale per scene without
# gsplat, the forward rows $3 and the forward + backward rows $4; logs named after $1.
variant_check() {
  eval "timeout \"${TEST_TIMEOUT:-200}\" python3 -m pytest -q -p no:cacheprovider \
    -n \"${TEST_WORKERS:-4}\" $2" 2>&1 | tail -3 | tee "$out/$1_tests.log"
  for s in $scenes; do
    timeout "${SCENE_TIMEOUT:-120}" python3 -m benchmarks.scale --no-gsplat --data carry/data \
      --scenes "$s" --rows "$3" --repeat 10 \
      --csv "$out/$1_fwd_$s.csv" 2>&1 | quiet > "$out/$1_fwd_$s.log"
  done
  grep -h " e2e \|raster" "$out"/"$1"_fwd_*.log
  for s in ${GRAD_SCENES:-guitar_x16_1080p guitar_x110_4k}; do
    timeout "${SCENE_TIMEOUT:-120}" python3 -m benchmarks.scale --grad --no-gsplat \
      --data carry/data --scenes "$s" --rows "$4" \
      --repeat 5 --csv "$out/$1_grad_$s.csv" 2>&1 | quiet > "$out/$1_grad_$s.log"
  done
  grep -h "grad:" "$out"/"$1"_grad_*.log
}
scenes="${SCENES:-guitar_720p guitar_x16_1080p guitar_x64_1080p guitar_x110_4k}"
case "${1:-grad}" in
  tests)
    # Each test named (-v); with pytest-timeout carried (carry/wheels), a test still running
    # after 150 s has every thread's stack dumped and its worker replaced: a kernel that hangs
    # waits in C, where the signal method never fires (Dec 3, eighth session).
    per_test=""
    python3 -c "import pytest_timeout" 2>/dev/null \
      && per_test="--timeout ${PER_TEST_TIMEOUT:-150} --timeout-method thread"
    timeout "${TEST_TIMEOUT:-300}" python3 -m pytest -v -p no:cacheprovider $per_test \
      -n "${TEST_WORKERS:-4}" ${TEST_ARGS:-tests/backends/test_backward_segments.py \
      tests/backends/test_gaussian_grads.py tests/backends/test_gradients.py \
      tests/backends/test_mosaic_staging.py} \
      -m 'slow or not slow' -rf --tb=short > "$out/tests.log" 2>&1
    grep "^FAILED\|passed\|failed\|Timeout\|crashed" "$out/tests.log" ;;
  grad)
    build_gsplat
    for s in $scenes; do
      timeout "${SCENE_TIMEOUT:-120}" python3 -m benchmarks.scale --grad --data carry/data \
        --scenes "$s" --rows "${GRAD_ROWS:-localgs,localgs@walked}" \
        --repeat 5 --csv "$out/grad_$s.csv" 2>&1 | quiet > "$out/grad_$s.log"
    done
    grep -h "grad:" "$out"/grad_*.log ;;
  fwd)
    build_gsplat
    for s in $scenes; do
      timeout "${SCENE_TIMEOUT:-110}" python3 -m benchmarks.scale --data carry/data \
        --scenes "$s" --rows "${FWD_ROWS:-localgs,vanilla,auto}" --repeat 10 \
        --csv "$out/fwd_$s.csv" 2>&1 | quiet > "$out/fwd_$s.log"
    done
    grep -h " e2e " "$out"/fwd_*.log ;;
  kernels)
    build_gsplat
    for s in ${SCENES:-guitar_x110_4k}; do
      timeout "${SCENE_TIMEOUT:-240}" python3 scripts/kernel_times.py --data carry/data \
        --scenes "$s" ${KT_ARGS:-} 2>&1 | quiet > "$out/kernels_$s.log"
    done
    grep -h "==" "$out"/kernels_*.log ;;
  train)
    timeout "${TRAIN_TIMEOUT:-500}" python3 benchmarks/train_vs_gsplat.py --data-root carry/data \
      --scenes ${TRAIN_SCENES:-skull} --steps "${STEPS:-7000}" --eval-every "${STEPS:-7000}" \
      --no-gsplat ${TRAIN_ARGS:-} --out "$out/train_${TRAIN_SCENES:-skull}" 2>&1 | tr '\r' '\n' \
      | grep -v "step/s\|s/step" > "$out/train.log"
    tail -6 "$out/train.log" ;;
  ahead)
    for flags in "" "--xla_gpu_force_compilation_parallelism=1"; do
      XLA_FLAGS="$flags" timeout "${AHEAD_TIMEOUT:-250}" python3 scripts/ahead_contention.py \
        ${AHEAD_ARGS:-} 2>&1 | quiet | tee -a "$out/ahead.log" | tail -4
    done ;;
  compact)
    variant_check compact "tests/backends/test_mosaic_staging.py -m 'slow or not slow' -k compact" \
      localgs:full,localgs,vanilla localgs:full,localgs,localgs:px128 ;;
  determinism)
    for run in ${DET_RUNS:-none:--no-compile-ahead none2:--no-compile-ahead thread:}; do
      name="${run%%:*}"; flag="${run#*:}"
      rm -rf "build/cache_$name"  # a compile of its own, not one a cache holds
      LGS_JAX_CACHE="$PWD/build/cache_$name" timeout "${RUN_TIMEOUT:-150}" python3 -m lgs_jax \
        fit --data carry/data/skull --out "build/det_$name" --overwrite --steps "${STEPS:-1500}" \
        --strategy mcmc --max-gaussians 500000 --eval-every "${STEPS:-1500}" $flag ${DET_ARGS:-} \
        2>&1 | tr '\r' '\n' \
        | grep "grown\|PSNR\|rror" > "$out/det_$name.log"
      python3 -c "import hashlib, sys, numpy as np; z = np.load(sys.argv[1]); h = hashlib.sha256()
[h.update(z[k].tobytes()) for k in sorted(z.files)]; print(sys.argv[2], h.hexdigest()[:16])" \
        "build/det_$name/checkpoint.npz" "$name" | tee -a "$out/determinism.log"
    done ;;
  *) echo "usage: $0 tests|grad|fwd|kernels|train|ahead|compact|determinism" >&2; exit 2 ;;
esac
