import os
import shutil

import jax
import pytest
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)  # float64 ground truth; float32 tests pass float32
# Persistent compilation cache: the tests of a session share compiled programs (the same
# program under another jit, the small programs of eager operations: reading one back costs
# less than compiling it again). A folder per
# pytest-xdist worker: JAX writes an entry in place, unlocked, so a worker sharing the folder
# could load an entry the other is still writing and crash; the lock that a size cap brings
# (`cli.cache_into`, the command line's) scans the whole folder at every write: the suite ran
# 958 s cold with it, 814 s with a folder per worker. Emptied when a session starts: CPU
# executables written by an earlier process crash some loads back into one that has run many
# programs (a segfault inside XLA's deserialization; docs/design-notes.md), while entries
# written and read within a session load fine.
_CACHE = os.environ.get("LGS_JAX_CACHE",
                        os.path.join(os.path.dirname(__file__), "..", ".jax_cache"))
_FOLDER = os.path.join(os.path.abspath(_CACHE), os.environ.get("PYTEST_XDIST_WORKER", "main"))
shutil.rmtree(_FOLDER, ignore_errors=True)
jax.config.update("jax_compilation_cache_dir", _FOLDER)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)

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


def pytest_collection_modifyitems(items):
    """tests/parallel first, the rest in their order: its child processes run the default set's
    longest tests (up to a minute each), which last in a pytest-xdist worker's share (the
    workers split the items in order) would end the run with the other worker idle."""
    items.sort(key=lambda item: not item.nodeid.startswith("tests/parallel/"))
