#!/usr/bin/env bash
# Mosaic GPU session: the Pallas tests on the GPU (Mosaic GPU and Triton kernels compiled), then
# the forward benchmark with Triton and Mosaic GPU rows and gsplat 1.5.3 in the same process.
# Run from the repository root on the device machine (scenes in carry/data, the gsplat wheel in
# carry/wheels); logs and CSV to $OUT.
set -uo pipefail
. "$(dirname "$0")/gpu_env.sh"
timeout "${TEST_TIMEOUT:-200}" python3 -m pytest -q -p no:cacheprovider -n 4 tests/backends/test_pallas.py tests/backends/test_mosaic_staging.py \
  -m 'slow or not slow' -k "mosaic or fast or kernel_equals" 2>&1 | tee "$out/mosaic_gpu_tests.log" | tail -4
echo "tests exit: ${PIPESTATUS[0]}"
d=carry/data
timeout "${BENCH_TIMEOUT:-330}" python3 -m benchmarks.render_vs_gsplat --repeat 20 --csv "$out/mosaic_bench.csv" \
  --rows "${ROWS:-pallas:triton,pallas:mosaic,pallas:mosaic:fast,pallas_vanilla:triton,pallas_vanilla:mosaic}" \
  --data "$d" --scene guitar@1280x720 --scene guitar@3840x2160 --scene lego_sh3@800x800 \
  --scene lego_sh3@3200x3200 \
  --scene "synthetic:1000000@1280x720" 2>&1 | grep -v "Warning\|to_torch" | tee "$out/mosaic_bench.log"
