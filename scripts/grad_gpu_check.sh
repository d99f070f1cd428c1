#!/usr/bin/env bash
# Gradient GPU session: the gradient and Pallas tests on the GPU (compiled Triton and Mosaic GPU
# kernels, forward and backward), then forward+backward of every differentiable backend against
# gsplat 1.5.3 in the same process. Run from the repository root on the device machine (scenes in
# carry/data, the gsplat wheel in carry/wheels); logs and CSV to $OUT.
set -uo pipefail
. "$(dirname "$0")/gpu_env.sh"
timeout "${TEST_TIMEOUT:-240}" python3 -m pytest -q -p no:cacheprovider -n 4 \
  tests/backends/test_gradients.py tests/backends/test_backward.py tests/backends/test_pallas.py -m 'slow or not slow' ${TEST_K:+-k "$TEST_K"} 2>&1 | tee "$out/grad_gpu_tests.log" | tail -4
echo "tests exit: ${PIPESTATUS[0]}"
d=carry/data
timeout "${BENCH_TIMEOUT:-300}" python3 -m benchmarks.render_vs_gsplat --grad --repeat 20 \
  --slow-repeat 3 --grad-rows "${GRAD_ROWS:-pallas,pallas:fast,pallas_vanilla}" --csv "$out/grad_bench.csv" \
  --data "$d" --scene guitar@1280x720 --scene lego_sh3@800x800 \
  --scene "lego200=$d/lego_sh3/lego_sh3.ply:$d/lego_sh3/lego_cameras.json@200x200" \
  --scene "synthetic:1000000@1280x720" 2>&1 | grep -v Warning | tee "$out/grad_bench.log"
