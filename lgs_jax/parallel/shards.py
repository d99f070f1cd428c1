"""A scene split across devices: Gaussians in contiguous blocks over the mesh axis "gaussians".

`shard_gaussians` pads the N Gaussians with all-zero rows (a zero quaternion: invalid, culled
by the projection, never in a tile list) to D·n rows, D the axis' size, and places block d,
global rows [d·n, (d + 1)·n), on the devices of position d along the axis (whole on each device
of another axis, "views", for data parallelism over views). The padding is the tail: every
block but the last holds n real Gaussians. `gather_gaussians` returns the N real ones, in order:
the global row order is the render's tie-break order, so a sharded scene renders as the whole
one does.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import NamedSharding, PartitionSpec

from ..scene import Gaussians, validate_gaussians

GAUSSIANS = "gaussians"  # the mesh axis the Gaussians are split over
VIEWS = "views"  # the mesh axis a batch of views is split over (data parallelism)


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class GaussianShards:
    """A scene of `num` Gaussians padded to `gaussians.num` = D·n rows, split in D blocks.

    Attributes:
      gaussians: the padded rows (rows from `num` on are all zero: invalid).
      num: the real Gaussians (static).
    """

    gaussians: Gaussians
    num: int = dataclasses.field(metadata=dict(static=True))

    @property
    def padding(self) -> int:
        return self.gaussians.num - self.num


def gaussian_mesh(gaussians: int, views: int = 1, devices=None) -> jax.sharding.Mesh:
    """A mesh of `views` x `gaussians` devices (the first ones of `jax.devices()` by default):
    1-D ("gaussians",) when views == 1, else 2-D ("views", "gaussians"), each row of the mesh
    one replica of the whole scene split `gaussians` ways."""
    shape, names = ((gaussians,), (GAUSSIANS,)) if views == 1 else ((views, gaussians),
                                                                    (VIEWS, GAUSSIANS))
    total = int(np.prod(shape))
    devices = jax.devices()[:total] if devices is None else list(devices)
    if len(devices) != total:
        raise ValueError(f"devices: the mesh needs {total} devices ({views} x {gaussians}), "
                         f"got {len(devices)}")
    auto = (jax.sharding.AxisType.Auto,) * len(shape)
    return jax.make_mesh(shape, names, devices=devices, axis_types=auto)


def shard_count(mesh: jax.sharding.Mesh) -> int:
    """D, the size of `mesh`'s "gaussians" axis (ValueError if it has none)."""
    if GAUSSIANS not in mesh.axis_names:
        raise ValueError(f"mesh: expected an axis named {GAUSSIANS!r}, got {mesh.axis_names}")
    return int(mesh.shape[GAUSSIANS])


def gaussian_sharding(mesh: jax.sharding.Mesh) -> NamedSharding:
    """Rows in blocks over "gaussians", whole along any other axis."""
    return NamedSharding(mesh, PartitionSpec(GAUSSIANS))


def padded_rows(num: int, devices: int) -> int:
    """D·n, the rows of `num` Gaussians split in `devices` equal blocks (at least one row each)."""
    return devices * max(-(-num // devices), 1)


def shard_gaussians(g: Gaussians, mesh: jax.sharding.Mesh) -> GaussianShards:
    """`g` padded (module docstring) and placed in blocks over `mesh`'s "gaussians" axis.

    Each device's block is cut from a host copy of `g` (`jax.make_array_from_callback`), so
    with several processes (`jax.distributed.initialize`) each process places the blocks of its
    own devices: every process passes the same `g` (or at least the rows its devices hold)."""
    validate_gaussians(g)
    rows = padded_rows(g.num, shard_count(mesh))
    sharding = gaussian_sharding(mesh)

    def place(x):
        x = np.asarray(x)
        x = np.concatenate([x, np.zeros((rows - x.shape[0],) + x.shape[1:], x.dtype)])
        return jax.make_array_from_callback(x.shape, sharding, lambda index: x[index])

    return GaussianShards(jax.tree.map(place, g), g.num)


def to_host(x):
    """`x` (an array, or a pytree of them) whole on the host, as numpy arrays: the one read of
    device values to the host that works with several processes (`jax.distributed`), where
    every process gets it all. An array that this process holds whole (one process, or all its
    blocks on this process's devices) is `np.asarray`; one whole on every device (replicated)
    is read from a device of this process; one split over devices of several processes is
    gathered (`multihost_utils.process_allgather`: a collective, so every process must make
    the same reads in the same order). The copies of the arrays held whole are all started
    before the first is awaited."""
    leaves, tree = jax.tree.flatten(x)
    for leaf in leaves:
        if isinstance(leaf, jax.Array) and leaf.is_fully_addressable:
            leaf.copy_to_host_async()
    return jax.tree.unflatten(tree, [_to_host(leaf) for leaf in leaves])


def _to_host(x) -> np.ndarray:
    if not isinstance(x, jax.Array) or x.is_fully_addressable:
        return np.asarray(x)
    if x.is_fully_replicated:
        return np.asarray(x.addressable_data(0))
    return np.asarray(multihost_utils.process_allgather(x, tiled=True))


def gather_gaussians(shards: GaussianShards) -> Gaussians:
    """The `num` real Gaussians as host numpy arrays, in global row order (one model: what a
    checkpoint or a PLY file holds), in every process."""
    return jax.tree.map(lambda x: to_host(x)[:shards.num], shards.gaussians)
