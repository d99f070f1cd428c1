"""Scenes larger than one device: Gaussian parallelism over a JAX device mesh.

`shard_gaussians(g, mesh)` splits a scene in contiguous blocks over the mesh axis "gaussians"
(`gaussian_mesh(d)`; `gaussian_mesh(d, views=v)` adds an axis "views" for data parallelism over
a batch of views); `render_sharded(shards, camera, mesh, ...)` renders it with one all-to-all of
projected records per view, bit-identical to `render` of the whole scene, and differentiable
(docs/multi-gpu.md). `balance.balanced_order` evens a sharded training pool's blocks.
"""

from .exchange import Traffic, record_width, traffic
from .gaussian_parallel import (ExchangeCapacityError, ShardedOutput, ShardedStats,
                                composite_sharded, count_sharded, grown_capacities,
                                render_sharded, render_sharded_growing)
from .shards import (GAUSSIANS, VIEWS, GaussianShards, gather_gaussians, gaussian_mesh,
                     gaussian_sharding, shard_gaussians, to_host)

__all__ = ["GAUSSIANS", "VIEWS", "ExchangeCapacityError", "GaussianShards", "ShardedOutput",
           "ShardedStats", "Traffic", "composite_sharded", "count_sharded", "gather_gaussians",
           "gaussian_mesh", "gaussian_sharding", "grown_capacities", "record_width",
           "render_sharded", "render_sharded_growing", "shard_gaussians", "to_host", "traffic"]
