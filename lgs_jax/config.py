"""Static rendering options (frozen, hashable: `jit` static arguments and part of its cache key).

`RasterConfig` says what to render (convention, the Local-GS switches, which Pallas
implementation); its `tuning` field, a `KernelConfig`, holds the kernels' performance settings,
which never change the image beyond the stated float32 tolerances. Both are values: a new
setting is a new config and a new compile, never a module global changed behind a cached trace.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

# Per-convention compositing constants (conventions.md, "Conventions").
ALPHA_MIN = 1.0 / 255.0
T_STOP = 1e-4
_ALPHA_CAP = {"3dgs": 0.99, "gsplat": 0.999}
CONVENTIONS = tuple(_ALPHA_CAP)
IMPLEMENTATIONS = ("triton", "mosaic")
PAIR_SOURCES = ("records", "gaussians")
BLOCK_ORDERS = ("sort", "buckets")


def _check(name: str, value, allowed):
    if value not in allowed:
        raise ValueError(f"{name}: expected one of {tuple(allowed)}, got {value!r}")


def _check_int(name: str, value, low: int):
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"{name}: expected an int >= {low}, got {value!r}")


@dataclasses.dataclass(frozen=True)
class KernelConfig:
    """Performance settings of the `pallas`, `pallas_vanilla` and `tiles` kernels.

    Implementation (RasterConfig.kernel="auto"):
      auto_localgs, auto_vanilla, auto_backward: the implementation "auto" runs on a GPU for the
        Local-GS forward, the vanilla forward and the backward ("triton" or "mosaic": the faster
        per kernel as measured, BENCHMARKS.md). In interpret mode "auto" runs Triton, whose
        interpreter (jitted XLA loops) is orders of magnitude faster than Mosaic GPU's
        simulation of a GPU; the two are bit for bit the same there.
      vanilla_from_pairs: a forward-only `pallas` render runs the vanilla kernel when
        its pair buffer (`capacity`) holds at least this many pairs (kernel "auto" only). Set
        when the Local-GS records were built in XLA, which cost more there than the kernel
        saved (H200: vanilla 8.39 against Local-GS 9.72 ms at 24M pairs); with the records
        built in the kernels (`mosaic_pair_source`) the two tied there (7.23 against 7.11 ms,
        memory 1072 against 1211 MiB), and with `mosaic_compact` Local-GS is the faster kernel
        at every size measured (2.69 against 3.45 ms at 24M pairs; BENCHMARKS.md §7), hence
        None by default (never). Images agree to float32 rounding (both are exact; the kernels
        evaluate α in different forms). Under differentiation the Local-GS forward and backward
        still run.
      interpret: run the Pallas kernels in interpret mode (True), lower them for the GPU (False:
        on a machine without one only tracing and lowering work, which tests use to check that
        every kernel lowers), or decide by the platform (None: interpret unless JAX's default
        backend is a GPU).

    Triton kernels:
      triton_unroll_localgs, triton_unroll_vanilla: pairs staged per loop iteration.

    Mosaic GPU kernels (a block is one 128-lane warpgroup):
      mosaic_unroll_localgs, mosaic_unroll_vanilla: pairs staged per loop iteration.
      mosaic_forward_pixels, mosaic_backward_pixels: pixels per block, 128 (half a tile, one per
        lane) or 256 (the whole tile, two per lane); None: by the image's tile count, whole
        tiles from `mosaic_whole_tile_from` tiles on. The backward's default is 256: its
        per-pair gradient rows are one per pair and block, so half tiles double them (44–48
        bytes per pair), and with the split backward whole tiles no longer cost time. H200,
        forward + backward against half-tile blocks (BENCHMARKS.md §7, Dec 3, fourth
        session): 1.59 against 1.60 ms and 64 against 79 MiB at 0.09M Gaussians (720p), 1.58
        against 1.64 ms at 0.06M (800x800), 3.36 against 3.46 ms and 283 against 331 MiB at
        1.45M (1080p, rows at the walked pairs), 7.06 against 6.93 ms and 1271 against 1751
        MiB at 5.8M (1080p); 4K already ran whole tiles.
      mosaic_chunk: pair records per TMA copy into shared memory, in the Local-GS forward
        and in the backward kernel (double-buffered; float32 only, TMA has no 64-bit float
        type); 0 reads records from global memory. A multiple of mosaic_unroll_localgs (a
        staged group never straddles two chunks).
      mosaic_pair_source: where the Local-GS Mosaic GPU kernels, forward and backward, get their
        pair records: "gaussians" (the default), built inside the kernels per chunk of 128
        pairs from per-Gaussian rows (lgs_jax.backends.mosaic_staging, the paper's staging: no
        per-pair buffer or XLA pass; float32 and float64; RenderStats.strip_pairs is then −1,
        not counted); "records", built for every pair in XLA before the kernels (staged per
        mosaic_chunk), which counts strip pairs. The Triton kernels read records either way.
        H200, same process as gsplat 1.5.3 (BENCHMARKS.md §7): forward 7.11 against 8.83 ms
        and 1211 against 2309 MiB at 10M Gaussians at 4K, forward+backward 18.63 against
        20.46 ms; equal within 0.04 ms on the 0.06M–0.09M scenes.
      mosaic_backward_segment: split each tile's backward walk into blocks of at most this many
        pairs (a multiple of mosaic_unroll_localgs), each entering with the transmittance,
        colour and depth the Local-GS Mosaic GPU forward stored at that pair
        (lgs_jax.backends.backward_segments); None: one block walks the whole list. The
        gradients match the unsplit walk's within float32 rounding (the sums behind a segment
        are C − C_hi, not a running sum) and are bitwise repeatable. H200, forward+backward
        at 5.8M Gaussians, 1080p (BENCHMARKS.md §7): 12.21 ms with 1024, 16.08 with None
        (gsplat: 10.95); with `render`'s row_capacity at the walked pairs 10.52 against 14.29.
      mosaic_compact: the Local-GS Mosaic GPU forward (where its records are built from
        Gaussians, blending is exact, warp_cull is on and mosaic_backward_segment
        is None or a multiple of 128; otherwise it walks every pair) keeps, of each staged
        chunk of 128 pairs, only those whose strip mask has a bit in the block's strips, packed
        first in shared memory (a stable partition: a ballot and a population count per warp,
        one exchange across the warps), and walks those: block-level culling, the paper's
        warp-level skip at the granularity Pallas gives a kernel. The pairs it drops blend
        nothing in the block's pixels (the masks are conservative), so the outputs are the full
        walk's: bit for bit in interpret mode and in float32 on the H200 (images and
        gradients), within 8e-15 in float64 there (the two kernels compile to other
        multiply-add contractions). With it the forward runs half-tile blocks unless
        mosaic_forward_pixels says otherwise. H200 (BENCHMARKS.md §7): the forward kernel 0.68x
        its time without at 5.8M Gaussians (1080p), 0.76x at 1.45M, 0.83x at 10M (4K), 0.95x
        at 0.09M (720p).
      mosaic_warp_lists: with mosaic_compact in half-tile blocks, each hardware warp (one strip)
        walks its own list of each chunk's pairs, those with its strip's bit, instead of every
        warp stepping through the pairs of any of the block's strips
        (lgs_jax.backends.mosaic_warp_lists: the paper's warp-level culling; the block still
        loops to its busiest warp's count). The same outputs as the full walk: bit for bit in
        interpret mode and on the H200 (images at six scenes of 1M–10M Gaussians, and the
        compaction's image and gradient tests). H200, the forward kernel against the
        block-compacted walk (BENCHMARKS.md §7, Dec 4, sixth session): 0.87x its time at
        synthetic 10M (4K), 0.84x at synthetic 4M (1080p), 0.92x at guitar x16 and lego x16
        (1080p), 0.91x at x64, 0.92x at x110 (4K).
      mosaic_image_layout: the Local-GS Mosaic GPU forward, in blocks of 128 pixels (what
        mosaic_compact runs), writes its colour as one (H, W, 3) image (the tiles' rows, a
        stride of 3 per channel) instead of three (n_tiles, 256) planes that XLA then
        interleaves into the image: the planes and the image are never live together, and XLA
        blends the background in place. Where the render's or the gradient's forward is another
        kernel, the planes. The same bits (images and gradients, float32 on the H200). Forward
        memory on the H200 (benchmarks.scale, BENCHMARKS.md §7 "Dec 3, seventh session"): 0.09M
        Gaussians at 720p 33 -> 27 MiB (gsplat 29), at 4K 264 -> 200 (gsplat 181); lego_sh3 at
        800x800 23 -> 19 (gsplat 19); time unchanged.
      mosaic_block_stops: in a render no gradient follows, the Local-GS Mosaic GPU forward
        stores each block's latest stop pair (a warpgroup maximum) instead of an int32 stop
        pair per pixel, and `RasterResult.stop` holds per-block stops for every forward (the
        one a gradient runs keeps its pixels' stops for the backward and reduces them alike):
        `stats.pairs_walked` reads only each tile's latest. With mosaic_image_layout, forward
        memory on the H200 at 0.09M Gaussians at 4K 200 -> 169 MiB (gsplat 181), at 720p
        27 -> 23 (29), lego_sh3 19 -> 16 (19).
      block_order: the order the Pallas kernels' blocks take tiles (forward) and segments (the
        split backward), longest first (lgs_jax.backends.block_order): "sort", a stable
        argsort of the lengths (CUB on GPUs from 16k keys: host time each call), or "buckets",
        a counting sort by buckets of four per octave (a few fused XLA passes), the default since
        Dec 5: only the schedule changes, never a bit; on the H200 forward 5.66 -> 5.58 ms at
        10M Gaussians at 4K, 4.46 -> 4.23 at guitar x110 4K, 2.43 -> 2.45 at 4M 1080p (noise),
        forward + backward 10.38 -> 10.07 and 7.23 -> 7.11 (BENCHMARKS.md §7, Dec 5, second
        session).

    `tiles` backend (XLA):
      tiles_group: strips processed together; tiles_chunk: Gaussians per staged batch (the fast
        blending mode tests its strip-wide stop once per batch).
    """

    auto_localgs: Literal["triton", "mosaic"] = "mosaic"
    auto_vanilla: Literal["triton", "mosaic"] = "mosaic"
    auto_backward: Literal["triton", "mosaic"] = "mosaic"
    interpret: bool | None = None
    vanilla_from_pairs: int | None = None
    triton_unroll_localgs: int = 2
    triton_unroll_vanilla: int = 8
    mosaic_unroll_localgs: int = 8
    mosaic_unroll_vanilla: int = 8
    mosaic_forward_pixels: int | None = None
    mosaic_backward_pixels: int | None = 256
    mosaic_whole_tile_from: int = 8192
    mosaic_chunk: int = 64
    mosaic_pair_source: Literal["records", "gaussians"] = "gaussians"
    mosaic_backward_segment: int | None = 1024
    mosaic_compact: bool = True
    mosaic_warp_lists: bool = True
    mosaic_image_layout: bool = True
    mosaic_block_stops: bool = True
    block_order: Literal["sort", "buckets"] = "buckets"
    tiles_group: int = 256
    tiles_chunk: int = 16

    def __post_init__(self):
        for name in ("auto_localgs", "auto_vanilla", "auto_backward"):
            _check(f"tuning.{name}", getattr(self, name), IMPLEMENTATIONS)
        _check("tuning.interpret", self.interpret, (None, True, False))
        for name in ("triton_unroll_localgs", "triton_unroll_vanilla", "mosaic_unroll_localgs",
                     "mosaic_unroll_vanilla", "tiles_group", "tiles_chunk"):
            _check_int(f"tuning.{name}", getattr(self, name), 1)
        for name in ("mosaic_forward_pixels", "mosaic_backward_pixels"):
            _check(f"tuning.{name}", getattr(self, name), (None, 128, 256))
        _check_int("tuning.mosaic_whole_tile_from", self.mosaic_whole_tile_from, 0)
        if self.vanilla_from_pairs is not None:
            _check_int("tuning.vanilla_from_pairs", self.vanilla_from_pairs, 1)
        _check_int("tuning.mosaic_chunk", self.mosaic_chunk, 0)
        _check("tuning.mosaic_pair_source", self.mosaic_pair_source, PAIR_SOURCES)
        _check("tuning.block_order", self.block_order, BLOCK_ORDERS)
        if self.mosaic_pair_source == "gaussians" and 128 % self.mosaic_unroll_localgs:
            raise ValueError(f"tuning.mosaic_unroll_localgs: must divide the 128 pairs of a "
                             f"chunk staged from Gaussians, got {self.mosaic_unroll_localgs}")
        if self.mosaic_backward_segment is not None:
            _check_int("tuning.mosaic_backward_segment", self.mosaic_backward_segment, 1)
            if self.mosaic_backward_segment % self.mosaic_unroll_localgs:
                raise ValueError(f"tuning.mosaic_backward_segment: {self.mosaic_backward_segment}"
                                 f" is not a multiple of mosaic_unroll_localgs="
                                 f"{self.mosaic_unroll_localgs} (set it to one, or to None for "
                                 f"whole walks)")
        for name in ("mosaic_compact", "mosaic_warp_lists", "mosaic_image_layout",
                     "mosaic_block_stops"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"tuning.{name}: expected a bool, got {getattr(self, name)!r}")
        if self.mosaic_chunk % self.mosaic_unroll_localgs:
            raise ValueError(f"tuning.mosaic_chunk: {self.mosaic_chunk} is not a multiple of "
                             f"mosaic_unroll_localgs={self.mosaic_unroll_localgs}")


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

    Implementation (the `pallas` backends only; same image either way):
      kernel: "triton" or "mosaic" (Mosaic GPU) Pallas kernels, forward and backward; "auto"
        takes `tuning.auto_*` per kernel on the GPU and Triton in interpret mode, and, under
        differentiation, the forward of the backward's implementation, so that forward and
        backward evaluate α with the same compiler's arithmetic.
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
