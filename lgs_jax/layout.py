"""Screen layout: 16x16 tiles, eight 16x2 strips per tile, pixel centres and hoisting frames.

The image is covered by tiles_x x tiles_y tiles of TILE x TILE pixels, numbered row-major. Within
a tile, pixel k (0..255) is row k // 16, column k % 16; strip s (0..7, one 32-lane warp in the
paper's kernel) holds rows 2s and 2s + 1, i.e. pixels 32s .. 32s + 31, so a strip's pixels are
consecutive k and (n_tiles·8, 32) strip arrays are (n_tiles, 256) tile arrays.

Pixel (i, j) of the image (row i, column j) has its centre at (j + 0.5, i + 0.5)
(docs/conventions.md).
Hoisting (Local-GS Eq. 1) evaluates ln α in a tile-local frame x' = pixel centre − origin, the
origin being the tile's top-left corner or its centre (`RasterConfig.origin`), or in global
coordinates (`local_coords=False`: x' = the pixel centre). Every coordinate here is an integer
plus 0.5 (or a multiple of 8), exact in any float format for images below 2^22 pixels a side.
"""

from __future__ import annotations

import jax.numpy as jnp

from .config import RasterConfig

TILE = 16
STRIPS = TILE // 2  # eight 16x2 strips per tile
STRIP_PIXELS = 2 * TILE  # 32: one warp
TILE_PIXELS = TILE * TILE


def tile_grid(width: int, height: int) -> tuple[int, int]:
    """Number of 16x16 tiles (tiles_x, tiles_y) covering a width x height image."""
    return -(-width // TILE), -(-height // TILE)


def tiles_to_image(x, width: int, height: int):
    """(tiles_y·tiles_x, 256, ...) per-tile pixel arrays -> (H·W, ...) row-major pixels (the
    partial tiles' pixels outside the image are dropped)."""
    tiles_x, tiles_y = tile_grid(width, height)
    rest = x.shape[2:]
    x = x.reshape((tiles_y, tiles_x, TILE, TILE) + rest)
    x = jnp.moveaxis(x, 2, 1).reshape((tiles_y * TILE, tiles_x * TILE) + rest)
    return x[:height, :width].reshape((height * width,) + rest)


def image_to_tiles(x, width: int, height: int):
    """(H·W, ...) row-major pixels -> (n_tiles, 256, ...) per tile, zero outside the image (the
    inverse of `tiles_to_image` on the image's pixels)."""
    tiles_x, tiles_y = tile_grid(width, height)
    rest = x.shape[1:]
    x = x.reshape((height, width) + rest)
    pad = [(0, tiles_y * TILE - height), (0, tiles_x * TILE - width)] + [(0, 0)] * len(rest)
    x = jnp.pad(x, pad).reshape((tiles_y, TILE, tiles_x, TILE) + rest)
    return jnp.moveaxis(x, 2, 1).reshape((tiles_x * tiles_y, TILE_PIXELS) + rest)


def tiled_image_to_tiles(image):
    """A (tiles_y·16, tiles_x·16, C) image (the whole tiles' pixels, as the Local-GS forward
    writes its colour: lgs_jax.backends.pallas.plan.Plan.image) -> (n_tiles, 256, C) per tile."""
    rows, cols = image.shape[:2]
    return image_to_tiles(image.reshape((rows * cols,) + image.shape[2:]), cols, rows)


def image_tiles(image, tile, tiles_x: int):
    """The channels of a (tiles_y·16, tiles_x·16, C) image at the pixels of tiles `tile` (any
    shape): C arrays tile.shape + (256,), pixel k of a tile at row k // 16, column k % 16 (a
    gather of those pixels only)."""
    k = jnp.arange(TILE_PIXELS, dtype=jnp.int32)
    tile = jnp.asarray(tile)[..., None]
    y = (tile // tiles_x) * TILE + k // TILE
    x = (tile % tiles_x) * TILE + k % TILE
    pixels = image[y, x]
    return tuple(pixels[..., c] for c in range(image.shape[-1]))


def pixel_centres(tile, k, tiles_x: int, dtype):
    """Centres of pixels k (0..255, broadcast with `tile`) of tiles `tile`: tile-local (lx, ly)
    relative to the tile corner and global (px, py), each in `dtype`."""
    lx = (k % TILE).astype(dtype) + 0.5
    ly = (k // TILE).astype(dtype) + 0.5
    px = ((tile % tiles_x) * TILE).astype(dtype) + lx
    py = ((tile // tiles_x) * TILE).astype(dtype) + ly
    return lx, ly, px, py


def tile_pixels(width: int, height: int, dtype):
    """Pixel centres (px, py), each (n_tiles, 256): every tile's pixels, row-major."""
    tiles_x, tiles_y = tile_grid(width, height)
    tile = jnp.arange(tiles_x * tiles_y, dtype=jnp.int32)[:, None]
    _, _, px, py = pixel_centres(tile, jnp.arange(TILE_PIXELS, dtype=jnp.int32)[None], tiles_x,
                                 dtype)
    return px, py


def strip_pixels(sid, tiles_x: int, dtype):
    """Pixel centres of strips `sid` (tile·8 + strip), each (n, 32): (lx, ly, px, py) as
    `pixel_centres`."""
    k = (sid % STRIPS)[:, None] * STRIP_PIXELS + jnp.arange(STRIP_PIXELS, dtype=jnp.int32)[None]
    return pixel_centres((sid // STRIPS)[:, None], k, tiles_x, dtype)


def origin_offset(config: RasterConfig) -> float:
    """Offset of the tile-local origin from the tile corner, in pixels (both axes)."""
    return TILE / 2 if config.origin == "center" else 0.0


def tile_origin_axis(t, config: RasterConfig, dtype):
    """One coordinate of the origin T of the hoisting frame (Eq. 1) for tile index `t` along an
    axis: the tile's corner or centre, 0 for global coords (exact: integers below 2^24)."""
    if not config.local_coords:
        return jnp.zeros(jnp.shape(t), dtype)
    return (t * TILE).astype(dtype) + origin_offset(config)


def tile_origin(tile_x, tile_y, config: RasterConfig, dtype):
    """Origin T of the hoisting frame (Eq. 1), (..., 2): `tile_origin_axis` of both axes."""
    return jnp.stack([tile_origin_axis(tile_x, config, dtype),
                      tile_origin_axis(tile_y, config, dtype)], -1)


def frame(lx, ly, px, py, config: RasterConfig):
    """The hoisting frame (x', y') of pixel centres: tile-local relative to the origin, or global
    without `local_coords`."""
    if not config.local_coords:
        return px, py
    off = origin_offset(config)
    return lx - off, ly - off
