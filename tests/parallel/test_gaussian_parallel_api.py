"""`lgs_jax.parallel`'s arguments and bookkeeping, in this process (one device; meshes of more
devices as `AbstractMesh`, which the checks read before anything compiles): bad arguments are
refused by name, overflowing buffers are grown by what they needed, and the exchange's bytes
are counted off-device only."""

import numpy as np
import pytest
from jax.sharding import AbstractMesh

import lgs_jax
from lgs_jax import parallel
from lgs_jax.parallel import ShardedStats
from tests import scenes


def _shards(rows=8, num=7):
    g = scenes.scene(0, n=rows, dtype=np.float32)
    return parallel.GaussianShards(g, num)


@pytest.mark.parametrize("mesh,backend,views,match", [
    (AbstractMesh((2,), ("x",)), None, None, "mesh: expected an axis named 'gaussians'"),
    (AbstractMesh((3,), ("gaussians",)), None, None, "shards: 8 rows do not split into 3 equal"),
    (AbstractMesh((2, 2), ("views", "gaussians")), None, 3,
     "camera: a mesh with 2 'views' splits a batch of cameras evenly; got 3"),
    (AbstractMesh((2,), ("gaussians",)), "brute", None, "backend: expected a tile backend"),
])
def test_gaussian_parallel_refuses_bad_arguments(mesh, backend, views, match):
    cam = scenes.camera(dtype=np.float32)
    if views is not None:
        cam = lgs_jax.stack_cameras([cam] * views)
    kwargs = dict(backend=backend) if backend else {}
    with pytest.raises(ValueError, match=match):
        parallel.render_sharded(_shards(), cam, mesh, capacity=8, exchange_capacity=8, **kwargs)


def test_gaussian_parallel_mesh_needs_its_devices():
    with pytest.raises(ValueError, match=r"devices: the mesh needs 6 devices \(2 x 3\), got 1"):
        parallel.gaussian_mesh(3, views=2, devices=[object()])


def _stats(pairs, counts, capacity=16, exchange=4):
    counts = np.asarray(counts)
    return ShardedStats(n_valid=0, n_invalid=0, n_transparent=0, n_unbounded=0,
                        pairs_required=np.asarray(pairs), capacity=capacity,
                        overflow=np.asarray(pairs).max() > capacity, exchange_counts=counts,
                        exchange_required=counts.max(), exchange_capacity=exchange,
                        exchange_overflow=counts.max() > exchange, backend="tiles")


def test_gaussian_parallel_grows_what_overflowed():
    fits = _stats([10, 16], [[4, 1], [0, 3]])
    assert parallel.grown_capacities(fits, 16, 4) is None
    assert parallel.grown_capacities(_stats([10, 16], [[4, 5], [0, 3]]), 16, 4) == (16, 8)
    assert parallel.grown_capacities(_stats([10, 17], [[4, 1], [0, 3]]), 16, 4) == (32, 4)
    both = {"a": _stats([100, 17], [[4, 1], [0, 3]]), "b": _stats([1, 1], [[9, 0], [0, 0]])}
    assert parallel.grown_capacities(both, 16, 4) == (128, 16)
    with pytest.raises(ValueError, match="holds no ShardedStats"):
        parallel.grown_capacities({"x": 1}, 16, 4)


def test_gaussian_parallel_growing_reruns_until_nothing_overflows():
    seen = []

    def fn(x, *, capacity, exchange_capacity):
        seen.append((capacity, exchange_capacity))
        return _stats([20, 3], [[x, 0], [0, 0]], capacity, exchange_capacity)

    _, capacity, exchange = parallel.render_sharded_growing(fn, 6, capacity=16,
                                                            exchange_capacity=2)
    assert seen == [(16, 2), (32, 8)] and (capacity, exchange) == (32, 8)


def test_gaussian_parallel_exchange_error_names_the_fix():
    err = parallel.ExchangeCapacityError(1000, 512)
    assert "pass exchange_capacity >= 1000 (e.g. 1024)" in str(err)


def test_gaussian_parallel_traffic_counts_off_device_records():
    t = parallel.traffic(np.asarray([[5, 2], [3, 7]]), capacity=8)
    assert (t.forward, t.backward) == (5 * 48, 5 * 48)
    assert t.buffer == 2 * 2 * 1 * 8 * 48  # both directions, 2 devices x 1 peer x 8 rows
    assert parallel.record_width(3) == 12 and parallel.record_width(1) == 10


def test_gaussian_parallel_refuses_a_band_mask_of_another_length():
    shards = _shards()
    k = shards.gaussians.sh.shape[1]
    with pytest.raises(ValueError, match=rf"sh_bands: expected shape \({k},\), got \({k + 1},\)"):
        parallel.render_sharded(shards, scenes.camera(dtype=np.float32),
                                AbstractMesh((2,), ("gaussians",)), capacity=8,
                                exchange_capacity=8, sh_bands=np.ones(k + 1, np.float32))
