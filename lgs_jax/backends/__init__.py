"""Rasterization backends: each maps (Projected, TileBins) to a final PixelState image."""
