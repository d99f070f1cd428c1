import glob
import os

# The default set compiles far more than it computes: on a machine without a GPU, XLA's CPU
# backend compiles without LLVM's expensive optimizations (about a quarter less time per
# compile). Tests compare paths compiled alike in one process; none asserts a timing.
if not glob.glob("/dev/nvidia[0-9]*"):
    os.environ["XLA_FLAGS"] = " ".join(filter(None, (
        os.environ.get("XLA_FLAGS"), "--xla_backend_optimization_level=0",
        "--xla_llvm_disable_expensive_passes=true")))

import jax  # noqa: E402
import pytest
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)  # float64 ground truth; float32 tests pass float32
# Persistent compilation cache: pytest-xdist workers (and reruns) share compiled kernels.
_CACHE = os.environ.get("LGS_JAX_CACHE",
                        os.path.join(os.path.dirname(__file__), "..", ".jax_cache"))
jax.config.update("jax_compilation_cache_dir", os.path.abspath(_CACHE))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

settings.register_profile("ci", max_examples=25, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=10, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("thorough", max_examples=300, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

DATA = os.environ.get("LGS_JAX_DATA",
                      os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data"))


@pytest.fixture(scope="session")
def data_dir():
    path = os.path.normpath(DATA)
    if not os.path.isdir(path):
        pytest.skip(f"real scenes not found at {path}")
    return path
