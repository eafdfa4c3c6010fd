"""SPH smoothing kernels (h is the compact support radius)."""
