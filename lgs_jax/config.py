"""Static rendering options (hashable, so they can be `jit` static arguments)."""

from __future__ import annotations

import dataclasses
from typing import Literal

# Per-convention compositing constants (conventions.md, "Conventions").
ALPHA_MIN = 1.0 / 255.0
T_STOP = 1e-4
_ALPHA_CAP = {"3dgs": 0.99, "gsplat": 0.999}


@dataclasses.dataclass(frozen=True)
class RasterConfig:
    """Frozen, hashable rendering options.

    Attributes:
      convention: "3dgs" (alpha cap 0.99; a pixel stops when T·(1−α) < 1e-4) or "gsplat"
        (gsplat 1.5.3: alpha cap 0.999; stops when T·(1−α) <= 1e-4).

    Local-GS switches (used by the `tiles` backend; the other backends ignore them):
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

    Implementation (the `pallas` backends only; same image either way):
      kernel: "triton" or "mosaic" (Mosaic GPU) Pallas kernels, forward and backward; "auto"
        takes the one measured faster per kernel (lgs_jax.backends.pallas.auto: on the GPU,
        Mosaic GPU for all three, the Local-GS and vanilla forwards and the backward; in
        interpret mode, without a GPU, Triton) and, under differentiation, the forward of the
        backward's implementation, so that forward and backward evaluate α with the same
        compiler's arithmetic.
    """

    convention: Literal["3dgs", "gsplat"] = "3dgs"
    blend: Literal["exact", "fast"] = "exact"
    hoist: bool = True
    warp_cull: bool = True
    local_coords: bool = True
    origin: Literal["corner", "center"] = "corner"
    kernel: Literal["auto", "triton", "mosaic"] = "auto"

    def __post_init__(self):
        if self.convention not in _ALPHA_CAP:
            raise ValueError(f"config.convention: expected '3dgs' or 'gsplat', "
                             f"got {self.convention!r}")
        if self.blend not in ("exact", "fast"):
            raise ValueError(f"config.blend: expected 'exact' or 'fast', got {self.blend!r}")
        if self.origin not in ("corner", "center"):
            raise ValueError(f"config.origin: expected 'corner' or 'center', got {self.origin!r}")
        if self.kernel not in ("auto", "triton", "mosaic"):
            raise ValueError(f"config.kernel: expected 'auto', 'triton' or 'mosaic', "
                             f"got {self.kernel!r}")
        for name in ("hoist", "warp_cull", "local_coords"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"config.{name}: expected a bool, got {getattr(self, name)!r}")

    @property
    def alpha_cap(self) -> float:
        return _ALPHA_CAP[self.convention]

    @property
    def stop_inclusive(self) -> bool:
        """Whether T·(1−α) == 1e-4 already stops the pixel (gsplat) or not (3DGS)."""
        return self.convention == "gsplat"
