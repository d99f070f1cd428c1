#!/usr/bin/env bash
# Pallas GPU session, part 1: the kernel tests on the GPU (compiled Triton kernels), lego_sh3
# against gsplat's held-out renders with the Pallas backends, and the kernel-only profile per CHUNK.
# Run from the repository root on the device machine (scenes in carry/data); logs to $OUT.
set -uo pipefail
out="${OUT:-out}"; mkdir -p "$out"
export PYTHONPATH="$PWD" LGS_JAX_DATA="$PWD/carry/data" HYPOTHESIS_PROFILE=ci PYTHONUNBUFFERED=1
export XLA_PYTHON_CLIENT_PREALLOCATE=false
timeout "${TEST_TIMEOUT:-300}" python3 -m pytest -q -p no:cacheprovider -n 4 \
  tests/test_pallas.py tests/test_real_scenes.py tests/test_binning.py 2>&1 \
  | tee "$out/pallas_gpu_tests.log" | tail -4
echo "tests exit: ${PIPESTATUS[0]}"
timeout "${SWEEP_TIMEOUT:-200}" python3 scripts/kernel_profile.py 2>&1 | grep -v Warning \
  | tee "$out/kernel_profile.log"
