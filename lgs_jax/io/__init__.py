"""Scene and camera file formats."""
