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
    """

    convention: Literal["3dgs", "gsplat"] = "3dgs"

    def __post_init__(self):
        if self.convention not in _ALPHA_CAP:
            raise ValueError(f"config.convention: expected '3dgs' or 'gsplat', "
                             f"got {self.convention!r}")

    @property
    def alpha_cap(self) -> float:
        return _ALPHA_CAP[self.convention]

    @property
    def stop_inclusive(self) -> bool:
        """Whether T·(1−α) == 1e-4 already stops the pixel (gsplat) or not (3DGS)."""
        return self.convention == "gsplat"
