"""Static rendering options (frozen, hashable: `jit` static arguments and part of its cache key).

`RasterConfig` says what to render (convention, the Local-GS switches, which Pallas
implementation); its `tuning` field, a `KernelConfig`, holds the kernels' performance settings,
which never change the image beyond the stated float32 tolerances. Both are values: a new
setting is a new config and a new compile, never a module global changed behind a cached trace.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

# Per-convention compositing constants (docs/conventions.md, "Conventions").
ALPHA_MIN = 1.0 / 255.0
T_STOP = 1e-4
_ALPHA_CAP = {"3dgs": 0.99, "gsplat": 0.999}
CONVENTIONS = tuple(_ALPHA_CAP)
IMPLEMENTATIONS = ("triton", "mosaic")
BLOCK_PIXELS = (None, 128, 256)
CHUNK = 128  # pairs the Mosaic GPU kernels stage per chunk (a warpgroup's lanes)


def _check(name: str, value, allowed):
    if value not in allowed:
        raise ValueError(f"{name}: expected one of {tuple(allowed)}, got {value!r}")


def _check_int(name: str, value, low: int):
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"{name}: expected an int >= {low}, got {value!r}")


@dataclasses.dataclass(frozen=True)
class KernelConfig:
    """Performance settings of the Pallas kernels (`pallas`, `pallas_vanilla` backends). None
    of them changes an image beyond float32 rounding: they choose block shapes and schedules.

    Attributes:
      unroll: pairs the Local-GS Mosaic GPU forward and backward evaluate per loop iteration
        (their α computed together, then blended in order); must divide the CHUNK = 128 pairs
        the kernels stage at a time.
      forward_pixels: pixels per Mosaic GPU forward block: 128 (half a 16x16 tile, four 16x2
        strips, one per hardware warp) or 256 (the whole tile, two pixels per lane); None: by
        the image's tile count (`whole_tile_from`). The compacted Local-GS forward (exact
        blending with warp culling, the default) always runs half tiles: each warp walks its
        own strip's pair list.
      backward_pixels: pixels per Mosaic GPU backward block, as `forward_pixels`. Whole tiles
        by default: the backward writes a gradient row per pair and block, so half tiles
        double the rows.
      whole_tile_from: with a block size of None, whole-tile blocks from this many tiles on
        (short lists: one block's per-tile work serves twice the pixels), half tiles below
        (long lists: two blocks stop independently).
      backward_segment: cut each tile's backward walk into blocks of at most this many pairs,
        each entering from the state the Local-GS Mosaic GPU forward stored there
        (lgs_jax.backends.pallas.segments): the kernel's length is then a segment rather than
        the longest list. A multiple of `unroll`; a multiple of 128 keeps the forward
        compacted (its checkpoints fall on chunk starts). None: one block per tile.
      interpret: run the Pallas kernels in interpret mode (True), lower them for the GPU
        (False: without a GPU only tracing and lowering work, which tests use to check that
        every kernel lowers), or decide by the platform (None: interpret unless JAX's default
        backend is a GPU).
    """

    unroll: int = 8
    forward_pixels: int | None = None
    backward_pixels: int | None = 256
    whole_tile_from: int = 8192
    backward_segment: int | None = 1024
    interpret: bool | None = None

    def __post_init__(self):
        _check_int("tuning.unroll", self.unroll, 1)
        if CHUNK % self.unroll:
            raise ValueError(f"tuning.unroll: must divide the {CHUNK} pairs of a staged chunk, "
                             f"got {self.unroll}")
        for name in ("forward_pixels", "backward_pixels"):
            _check(f"tuning.{name}", getattr(self, name), BLOCK_PIXELS)
        _check_int("tuning.whole_tile_from", self.whole_tile_from, 0)
        if self.backward_segment is not None:
            _check_int("tuning.backward_segment", self.backward_segment, 1)
            if self.backward_segment % self.unroll:
                raise ValueError(f"tuning.backward_segment: {self.backward_segment} is not a "
                                 f"multiple of unroll={self.unroll} (set it to one, or to None "
                                 f"for whole walks)")
        _check("tuning.interpret", self.interpret, (None, True, False))


@dataclasses.dataclass(frozen=True)
class RasterConfig:
    """Frozen, hashable rendering options.

    Attributes:
      convention: "3dgs" (alpha cap 0.99; a pixel stops when T·(1−α) < 1e-4) or "gsplat"
        (gsplat 1.5.3: alpha cap 0.999; stops when T·(1−α) <= 1e-4).
      antialiased: scale each Gaussian's opacity by sqrt(det(J Σc Jᵀ) / det(J Σc Jᵀ + 0.3 I)),
        so that the 0.3-pixel dilation keeps its integral (gsplat's
        rasterize_mode="antialiased", Mip-Splatting's 2D filter; lgs_jax.projection); False
        (default): the original 3DGS dilation, which brightens and thickens Gaussians smaller
        than a pixel. Every backend; scenes trained with it should be rendered with it.

    Local-GS switches (the `tiles` and `pallas` backends; `brute`, `reference` and
    `pallas_vanilla` compute the contract's difference form and honour only `convention` and,
    for `pallas_vanilla`, `blend`):
      blend: "exact" (per-pixel termination and alpha tests as masks: the contract's image) or
        "fast" (the paper's warp-coherent blending, Sec. III-D: a 16x2 strip stops only when all
        32 pixels have T < 1e-4; deviates from the contract by at most 1e-4/(1 − cap)·max|rgb −
        background| per pixel, see lgs_jax.backends.tiles).
      hoist: evaluate ln α as V·[x'², x'y', y'², x', y', 1] (Eq. 8–10) instead of the
        difference form.
      warp_cull: per-strip Gaussian lists from the 8-bit strip masks (Sec. III-C, Eq. 13–21).
      local_coords: hoist in tile-local coordinates (Eq. 1–3); False expands in global screen
        coordinates (the paper's "w/o Local Coord", Table V).
      origin: tile-local origin, "corner" (the paper's Eq. 1) or "center" of the 16x16 tile.

    Implementation (the `pallas` backends only; the same image either way):
      kernel: the Pallas kernels' lowering, forward and backward alike: "mosaic" (Mosaic GPU,
        the GPU kernels: Hopper) or "triton" (Pallas Triton: interpret mode's fast path, and
        GPUs Mosaic GPU does not target); "auto": Mosaic GPU on a GPU, Triton in interpret
        mode (Mosaic GPU's interpreter simulates the GPU, orders of magnitude slower).
      tuning: the kernels' performance settings (`KernelConfig`).
    """

    convention: Literal["3dgs", "gsplat"] = "3dgs"
    antialiased: bool = False
    blend: Literal["exact", "fast"] = "exact"
    hoist: bool = True
    warp_cull: bool = True
    local_coords: bool = True
    origin: Literal["corner", "center"] = "corner"
    kernel: Literal["auto", "triton", "mosaic"] = "auto"
    tuning: KernelConfig = KernelConfig()

    def __post_init__(self):
        _check("config.convention", self.convention, CONVENTIONS)
        _check("config.blend", self.blend, ("exact", "fast"))
        _check("config.origin", self.origin, ("corner", "center"))
        _check("config.kernel", self.kernel, ("auto",) + IMPLEMENTATIONS)
        for name in ("antialiased", "hoist", "warp_cull", "local_coords"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"config.{name}: expected a bool, got {getattr(self, name)!r}")
        if not isinstance(self.tuning, KernelConfig):
            raise ValueError(f"config.tuning: expected a KernelConfig, got "
                             f"{type(self.tuning).__name__}")

    @property
    def alpha_cap(self) -> float:
        return _ALPHA_CAP[self.convention]

    @property
    def stop_inclusive(self) -> bool:
        """Whether T·(1−α) == 1e-4 already stops the pixel (gsplat) or not (3DGS)."""
        return self.convention == "gsplat"
