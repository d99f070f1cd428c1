"""The rasterization backends, by name (lgs_jax.backends.interface says what a backend is).

To add a backend, write its module (a `rasterize` returning `RasterResult`, wrapped in a
`Backend`) and add it to `REGISTRY` below; `render` and the CLI find it here.
"""

from . import brute, pallas, reference, tiles
from .interface import Backend, BackendInputs, RasterResult

REGISTRY: dict[str, Backend] = {b.name: b for b in (
    brute.BACKEND, reference.BACKEND, tiles.BACKEND, pallas.LOCALGS, pallas.VANILLA)}

__all__ = ["REGISTRY", "Backend", "BackendInputs", "RasterResult"]
