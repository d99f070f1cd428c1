"""Benchmarks of lgs_jax, run from the repository root as `python -m benchmarks.<name>`.

  ablation          every backend and Local-GS switch on one scene and camera: run time against
                    the error to the float64 reference (the paper's Tables IV and V; CPU or GPU)
  render_vs_gsplat  the Pallas kernels against gsplat 1.5.3 in one process: stages, rasterization,
                    end to end, memory, PSNR; `--grad` for forward + backward (GPU)
  scale             0.06M–10M Gaussians at 720p–4K against gsplat, forward or `--grad` (GPU)
  train_vs_gsplat   our trainer and gsplat's (Default/MCMC strategies), same data, split, steps
                    and rates: held-out PSNR/SSIM curves, time per step, peak memory (GPU)

Each module's docstring gives its command line. A new benchmark is a module here that takes its
data folder, timing, PSNR, scene specs and rows from `benchmarks.common`; its raw output goes to
bench_results/DEVICE-YYYY-MM/ and its numbers, with the command, to BENCHMARKS.md.
"""
