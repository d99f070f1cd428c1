#!/usr/bin/env bash
# One GPU session: the exactness tests on the GPU (where TF32 would show), then the benchmark.
# Run from the repository root on the device machine, with the real scenes copied to
# carry/data (guitar, lego_sh3). Results go to $OUT (or ./out).
set -uo pipefail
out="${OUT:-out}"; mkdir -p "$out"
export PYTHONPATH="$PWD" LGS_JAX_DATA="$PWD/carry/data" HYPOTHESIS_PROFILE=ci PYTHONUNBUFFERED=1
python3 -c 'import jax; print("jax", jax.__version__, jax.devices())' 2>&1 | tail -1
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
timeout "${TEST_TIMEOUT:-300}" python3 -m pytest -q -x -p no:cacheprovider -n 0 \
  tests/backends/test_tiles.py tests/backends/test_reference.py tests/test_real_scenes.py 2>&1 \
  | tee "$out/gpu_tests.log" | tail -4
echo "tests exit: ${PIPESTATUS[0]}"
timeout "${BENCH_TIMEOUT:-400}" python3 -m benchmarks.ablation --repeat 20 --csv "$out/bench_gpu.csv" \
  --data carry/data --scene guitar@1280x720 --scene lego_sh3@800x800 \
  --scene "synthetic:1000000@1280x720" 2>&1 | grep -v "^WARNING\|^I1122\|^E1122" \
  | tee "$out/bench_gpu.log" | tail -45
