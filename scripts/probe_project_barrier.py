"""Experiment: kernel_times of the forward (and gradient) with the projection's outputs behind an
optimization barrier (each field materialised once instead of fused into its consumers).

    python scripts/probe_project_barrier.py [kernel_times arguments]
"""
import importlib
import os
import sys

from jax import lax

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from scripts import kernel_times  # noqa: E402

R = importlib.import_module("lgs_jax.render")
_project = R.project
R.project = lambda g, cam: lax.optimization_barrier(_project(g, cam))
sys.exit(kernel_times.main())
