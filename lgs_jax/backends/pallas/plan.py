"""What runs for one Pallas rasterization (`plan`): the kernels' lowering, interpret mode, block
sizes and output layouts, resolved once per trace from the `RasterConfig`, the image's tile
count and the backward's row capacity."""

from __future__ import annotations

import dataclasses

import jax

from ...config import RasterConfig
from .mosaic_forward import compacts


@dataclasses.dataclass(frozen=True)
class Plan:
    """Everything static about one Pallas rasterization (hashable: a custom_vjp's static
    argument).

    Attributes:
      config: the RasterConfig rendered.
      vanilla: the vanilla kernel (the original 3DGS rasterizer), else Local-GS.
      kernel: "mosaic" or "triton", the lowering of every kernel of the rasterization.
      interpret: the kernels run in Pallas interpret mode.
      forward_pixels, backward_pixels: Mosaic GPU pixels per block (128 or 256).
      rows: the backward's row capacity (render's `row_capacity`), None for one row per pair
        slot.
      image: the forward writes its colour as one (tiles_y·16, tiles_x·16, 3) image, else as
        per-tile planes (the half-tile Local-GS Mosaic GPU forward).
      block_stops: the stop pairs a render returns are each block's latest, (n_tiles, 256 /
        forward_pixels) (the Local-GS Mosaic GPU forward), rather than each pixel's.
    """

    config: RasterConfig
    vanilla: bool
    kernel: str
    interpret: bool
    forward_pixels: int
    backward_pixels: int
    rows: int | None = None
    image: bool = False
    block_stops: bool = False

    @property
    def kernel_name(self) -> str:
        """The forward kernel, e.g. "localgs-mosaic" (the stats' `kernel`)."""
        return f"{'vanilla' if self.vanilla else 'localgs'}-{self.kernel}"

    @property
    def model(self) -> RasterConfig:
        """The α arithmetic the backward walks: the config's, or for the vanilla kernel the
        difference form on the tile's whole list (the Local-GS backward with hoist and
        warp_cull off)."""
        if self.vanilla:
            return dataclasses.replace(self.config, hoist=False, warp_cull=False)
        return self.config

    @property
    def segment(self) -> int | None:
        """The backward's segment length (`KernelConfig.backward_segment`) where it applies: a
        Local-GS Mosaic GPU forward stores the checkpoints a split walk enters from."""
        local_mosaic = self.kernel == "mosaic" and not self.vanilla
        return self.config.tuning.backward_segment if local_mosaic else None


def interpreted(config: RasterConfig) -> bool:
    """Whether the kernels run in interpret mode (`KernelConfig.interpret`; by default when JAX's
    default backend is not a GPU)."""
    interpret = config.tuning.interpret
    return jax.default_backend() != "gpu" if interpret is None else interpret


def block_pixels(fixed: int | None, n_tiles: int, config: RasterConfig) -> int:
    """Pixels per Mosaic GPU block: `fixed` if set, else whole tiles (256) from
    `tuning.whole_tile_from` tiles on and half tiles (128) below."""
    if fixed is not None:
        return fixed
    return 256 if n_tiles >= config.tuning.whole_tile_from else 128


def plan(config: RasterConfig, vanilla: bool, n_tiles: int, rows: int | None = None) -> Plan:
    """Resolve `config` for an image of `n_tiles` tiles on this platform (`rows`: the
    backward's row capacity). `RasterConfig.kernel` "auto" is Mosaic GPU on a GPU and Triton
    in interpret mode."""
    t = config.tuning
    interpret = interpreted(config)
    kernel = config.kernel if config.kernel != "auto" else ("triton" if interpret else "mosaic")
    local_mosaic = kernel == "mosaic" and not vanilla
    forward_pixels = 128 if (not vanilla and compacts(config)) else t.forward_pixels
    forward_pixels = block_pixels(forward_pixels, n_tiles, config)
    return Plan(config=config, vanilla=vanilla, kernel=kernel, interpret=interpret,
                forward_pixels=forward_pixels,
                backward_pixels=block_pixels(t.backward_pixels, n_tiles, config), rows=rows,
                image=local_mosaic and forward_pixels == 128, block_stops=local_mosaic)
