#!/usr/bin/env bash
# The GPU session: the GPU test set, then a benchmark against gsplat 1.5.3. Each part fits one
# device call of 10 minutes; run them as separate calls where the time is short:
#
#   bash scripts/gpu_check.sh              # tests, then fwd (the default)
#   bash scripts/gpu_check.sh tests        # the kernel, gradient, staging, binning, projection
#                                          # and real-scene tests with the compiled kernels, slow
#                                          # set included (about 4 minutes on 8 workers)
#   bash scripts/gpu_check.sh fwd          # benchmarks.scale, forward, per scene (BENCHMARKS.md)
#   bash scripts/gpu_check.sh grad         # benchmarks.scale --grad, per scene
#   bash scripts/gpu_check.sh train        # fit on skull, 7k steps, ms per step (no gsplat)
#   bash scripts/gpu_check.sh kernels      # every kernel's device time (scripts/kernel_times.py)
#
# Environment: SCENES (benchmarks.common.SCENES names; default guitar_720p guitar_x16_1080p
# guitar_x110_4k), FWD_ROWS, GRAD_ROWS, REPEAT, TEST_ARGS (pytest arguments replacing the
# test set), TEST_WORKERS, TEST_TIMEOUT, SCENE_TIMEOUT, TRAIN_SCENES, STEPS, TRAIN_ARGS,
# KT_ARGS. Run from the repository root on the device machine, with the real scenes in
# carry/data and the gsplat wheel in carry/wheels (scripts/gpu_env.sh). Logs and CSVs go to
# $OUT (default ./out), one benchmark process per scene so that a failing row costs one scene;
# lines are written as they come, so a call cut by its time limit keeps them.
set -uo pipefail
. "$(dirname "$0")/gpu_env.sh"
export LGS_JAX_CACHE="$PWD/build/jax_cache"
scenes="${SCENES:-guitar_720p guitar_x16_1080p guitar_x110_4k}"
quiet() { grep --line-buffered -v "Warning\|warn(\|t = lambda"; }

# gsplat's CUDA extension, built once before any timed process (a build killed by a scene's
# time limit leaves torch's lock file behind, on which every later import waits).
build_gsplat() {
  timeout 240 python3 -c "from gsplat.cuda._backend import _C; assert _C is not None" 2>&1 \
    | grep --line-buffered "set up\|rror" | tee "$out/gsplat_build.log"
}

tests() {
  # Each test named (-v). With pytest-timeout installed, a test still running after
  # PER_TEST_TIMEOUT seconds has its stacks dumped and its worker replaced: a kernel that does
  # not build for the GPU can hang in C, where a signal never fires.
  local per_test=""
  python3 -c "import pytest_timeout" 2>/dev/null \
    && per_test="--timeout ${PER_TEST_TIMEOUT:-150} --timeout-method thread"
  timeout "${TEST_TIMEOUT:-420}" python3 -m pytest -v -p no:cacheprovider $per_test \
    -n "${TEST_WORKERS:-8}" ${TEST_ARGS:-tests/backends tests/test_binning.py \
    tests/test_projection.py tests/test_colors.py tests/test_real_scenes.py} \
    -m 'slow or not slow' -rf --tb=short > "$out/tests.log" 2>&1
  grep "^FAILED\|passed\|failed\|Timeout\|crashed" "$out/tests.log"
}

fwd() {
  build_gsplat
  for s in $scenes; do
    timeout "${SCENE_TIMEOUT:-150}" python3 -m benchmarks.scale --data carry/data --scenes "$s" \
      --rows "${FWD_ROWS:-localgs,vanilla}" --repeat "${REPEAT:-20}" --big-repeat "${REPEAT:-20}" \
      --csv "$out/fwd_$s.csv" 2>&1 | quiet > "$out/fwd_$s.log"
  done
  grep -h " e2e " "$out"/fwd_*.log
}

grad() {
  build_gsplat
  for s in $scenes; do
    timeout "${SCENE_TIMEOUT:-150}" python3 -m benchmarks.scale --grad --data carry/data \
      --scenes "$s" --rows "${GRAD_ROWS:-localgs,localgs@walked}" --repeat "${REPEAT:-10}" \
      --big-repeat "${REPEAT:-10}" --csv "$out/grad_$s.csv" 2>&1 | quiet > "$out/grad_$s.log"
  done
  grep -h "grad:" "$out"/grad_*.log
}

train() {
  for s in ${TRAIN_SCENES:-skull}; do
    timeout "${TRAIN_TIMEOUT:-500}" python3 benchmarks/train_vs_gsplat.py --data-root carry/data \
      --scenes "$s" --steps "${STEPS:-7000}" --eval-every "${STEPS:-7000}" --no-gsplat \
      ${TRAIN_ARGS:-} --out "$out/train_$s" 2>&1 | tr '\r' '\n' \
      | grep -v "step/s\|s/step" > "$out/train_$s.log"
    tail -6 "$out/train_$s.log"
  done
}

kernels() {
  build_gsplat
  for s in $scenes; do
    timeout "${SCENE_TIMEOUT:-240}" python3 scripts/kernel_times.py --data carry/data \
      --scenes "$s" ${KT_ARGS:-} 2>&1 | quiet > "$out/kernels_$s.log"
  done
  grep -h "==" "$out"/kernels_*.log
}

parts=("$@")
[ ${#parts[@]} -eq 0 ] && parts=(tests fwd)
for part in "${parts[@]}"; do
  case "$part" in
    tests|fwd|grad|train|kernels) echo "== $part"; "$part" ;;
    *) echo "usage: $0 [tests|fwd|grad|train|kernels ...]" >&2; exit 2 ;;
  esac
done
