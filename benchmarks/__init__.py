"""Benchmarks of lgs_jax, run from the repository root as `python -m benchmarks.<name>`."""
