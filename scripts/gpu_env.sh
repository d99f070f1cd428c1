# Sourced by scripts/gpu_check.sh (and by any one-off GPU call): $out for logs, the carried wheels
# (gsplat 1.5.3, pytest-timeout) installed to /tmp/site, and the environment the tests and
# benchmarks expect (scenes in carry/data, no JAX preallocation so that gsplat gets GPU memory).
out="${OUT:-out}"; mkdir -p "$out"
if compgen -G "carry/wheels/*.whl" > /dev/null; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site carry/wheels/*.whl
fi
export PYTHONPATH="/tmp/site:$PWD" LGS_JAX_DATA="$PWD/carry/data" PYTHONUNBUFFERED=1
export XLA_PYTHON_CLIENT_PREALLOCATE=false HYPOTHESIS_PROFILE="${HYPOTHESIS_PROFILE:-dev}"
# gsplat's CUDA extension builds once per machine (about 75 s); keep it in the git-ignored build/
# folder so that later calls on the same warm machine reuse it.
export TORCH_EXTENSIONS_DIR="$PWD/build/torch_extensions"
python3 -c 'import jax; print("jax", jax.__version__, jax.devices())' 2>&1 | tail -1
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null || true
