"""The device the tests run on, and the mark of cases only a GPU runs (their interpret-mode run
on a CPU would cost CI minutes that another case already spends on the same code)."""

import jax
import pytest

ON_GPU = jax.default_backend() == "gpu"


def gpu_only(reason: str):
    """A mark skipping the case off GPUs, saying why."""
    return pytest.mark.skipif(not ON_GPU, reason=reason)
