"""Image-level helpers shared by the algorithms and the recorder (JPEG restart-segment regions)."""
