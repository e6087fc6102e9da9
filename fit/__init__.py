"""Inverse reconstruction with ks_jax (MODEL.md section 6, `ks-jax fit`)."""
