"""A small 3DGS training loop on optax: fixed Gaussian count, L1 + D-SSIM, per-group Adam.

    python -m lgs_jax fit --data ../shared/data/lego_train --steps N --out DIR
        [--resume | --overwrite] [--backend reference|tiles|pallas|pallas_vanilla]

Pieces (each usable alone):
  `ssim`            SSIM with an 11x11 Gaussian window (σ = 1.5), reflect padding, the map
                    averaged away from a 5-pixel border: skimage's
                    `structural_similarity(gaussian_weights=True, sigma=1.5,
                    use_sample_covariance=False, data_range=1)` (tests compare them).
  `loss_fn`         (1 − λ)·L1 + λ·(1 − SSIM), λ = 0.2 (3DGS).
  `optimizer`       Adam per parameter group through `optax.partition`, the 3DGS learning rates
                    (means decayed exponentially from 1.6e-4 to 1.6e-6 times the scene extent).
  `sh_mask`         the SH-degree schedule: one more band every `sh_every` steps.
  `fit`             the loop: capacity grown whenever a batch overflows (never a silent drop),
                    a tqdm progress bar, metrics log (JSONL), checkpoints (scene as INRIA PLY plus
                    the optimizer state, so a run resumes), held-out evaluation with
                    scikit-image PSNR/SSIM and renders of the held-out views. A run directory
                    holds one run: a non-empty one needs resume or overwrite.
Gradients come from the chosen backend's custom_vjp (lgs_jax.backends.backward; the Pallas
backends' backward kernel on GPUs). The default is `pallas` on GPUs and `tiles` elsewhere (the
Pallas kernels run interpreted, slowly, without a GPU).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import re
import threading
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax
import tqdm

from .io.cameras import load_cameras
from .io.ply import load_ply, save_ply
from .render import next_pow2, render
from .scene import Gaussians, stack_cameras

LAMBDA_DSSIM = 0.2
GROUPS = ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest")


def _gaussian_window(sigma=1.5, radius=5):
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    w = np.exp(-0.5 * (x / sigma) ** 2)
    return w / w.sum()


def _blur(x, w):
    """Separable filter of (..., H, W) images with scipy.ndimage's 'reflect' boundary."""
    r = (len(w) - 1) // 2
    w = jnp.asarray(w, x.dtype)
    x = jnp.pad(x, [(0, 0)] * (x.ndim - 2) + [(r, r), (r, r)], mode="symmetric")
    h, wd = x.shape[-2] - 2 * r, x.shape[-1] - 2 * r
    x = sum(w[i] * x[..., i:i + h, :] for i in range(len(w)))
    return sum(w[i] * x[..., :, i:i + wd] for i in range(len(w)))


def ssim(a, b, data_range=1.0):
    """Mean SSIM of two (H, W, C) images (see module docstring for the exact definition)."""
    w = _gaussian_window()
    a, b = jnp.moveaxis(a, -1, 0), jnp.moveaxis(b, -1, 0)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    mu_a, mu_b = _blur(a, w), _blur(b, w)
    var_a = _blur(a * a, w) - mu_a**2
    var_b = _blur(b * b, w) - mu_b**2
    cov = _blur(a * b, w) - mu_a * mu_b
    s = ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a**2 + mu_b**2 + c1) * (var_a + var_b + c2))
    return jnp.mean(s[:, 5:-5, 5:-5])


def loss_fn(image, target):
    """(1 − λ)·L1 + λ·(1 − SSIM), λ = 0.2."""
    l1 = jnp.mean(jnp.abs(image - target))
    return (1 - LAMBDA_DSSIM) * l1 + LAMBDA_DSSIM * (1 - ssim(image, target))


@dataclasses.dataclass(frozen=True)
class Settings:
    """3DGS defaults (learning rates per group; steps of the SH schedule)."""

    lr_means: float = 1.6e-4
    lr_means_final: float = 1.6e-6
    lr_quats: float = 1e-3
    lr_log_scales: float = 5e-3
    lr_logit_opacities: float = 5e-2
    lr_sh_dc: float = 2.5e-3
    lr_sh_rest: float = 2.5e-3 / 20
    sh_every: int = 1000
    batch: int = 1
    eval_every: int = 500
    checkpoint_every: int = 1000


def _split(g: Gaussians):
    return dict(means=g.means, quats=g.quats, log_scales=g.log_scales,
                logit_opacities=g.logit_opacities, sh_dc=g.sh[:, :1], sh_rest=g.sh[:, 1:])


def _join(params) -> Gaussians:
    return Gaussians(params["means"], params["quats"], params["log_scales"],
                     params["logit_opacities"],
                     jnp.concatenate([params["sh_dc"], params["sh_rest"]], 1))


def optimizer(steps: int, extent: float, s: Settings = Settings()):
    """Adam per parameter group (optax.partition); means' rate decays exponentially."""
    means = optax.exponential_decay(s.lr_means * extent, steps,
                                    s.lr_means_final / s.lr_means, end_value=s.lr_means_final
                                    * extent)
    rates = dict(means=means, quats=s.lr_quats, log_scales=s.lr_log_scales,
                 logit_opacities=s.lr_logit_opacities, sh_dc=s.lr_sh_dc, sh_rest=s.lr_sh_rest)
    return optax.partition({k: optax.adam(v, eps=1e-15) for k, v in rates.items()},
                           {k: k for k in GROUPS})


def sh_mask(step, num_bases: int, every: int):
    """(num_bases,) mask of the SH bands in use at `step`: degree min(step // every, max)."""
    degree = jnp.minimum(step // every, int(round(np.sqrt(num_bases))) - 1)
    band = jnp.asarray([int(np.sqrt(k)) for k in range(num_bases)])
    return (band <= degree).astype(jnp.float32)


def random_init(n: int, center, radius: float, sh_bases: int = 16, seed: int = 0) -> Gaussians:
    """N Gaussians uniform in a ball: grey, opacity 0.1, isotropic scale ~ the mean spacing."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d *= (radius * rng.uniform(0, 1, n) ** (1 / 3) / np.linalg.norm(d, axis=1))[:, None]
    spacing = radius * (4 / 3 * np.pi / n) ** (1 / 3)
    sh = np.zeros((n, sh_bases, 3))
    sh[:, 0] = rng.normal(0, 0.1, (n, 3))
    f32 = lambda x: np.asarray(x, np.float32)
    return Gaussians(f32(np.asarray(center) + d), f32(np.tile([1.0, 0, 0, 0], (n, 1))),
                     f32(np.full((n, 3), np.log(spacing))), f32(np.full(n, np.log(0.1 / 0.9))),
                     f32(sh))


def load_nerf(data: str, background=(1.0, 1.0, 1.0)):
    """(cameras, images (N, H, W, 3) composited over `background`, ids) of a NeRF-synthetic
    folder (transforms_train.json + train/r_*.png)."""
    import matplotlib.image

    path = os.path.join(data, "transforms_train.json")
    frames = json.load(open(path))["frames"]
    cams = load_cameras(path)
    images, ids = [], []
    for f in frames:
        rgba = matplotlib.image.imread(os.path.join(data, f["file_path"] + ".png"))
        images.append(rgba[..., :3] * rgba[..., 3:] + np.asarray(background) * (1 - rgba[..., 3:]))
        ids.append(int(re.findall(r"\d+", os.path.basename(f["file_path"]))[-1]))
    return cams, np.stack(images).astype(np.float32), np.asarray(ids)


class _Progress:
    """A tqdm progress bar on stderr (step, loss, it/s, ETA) that is redrawn every `interval`
    seconds, also while one step runs (the first step compiles, for minutes on a CPU)."""

    def __init__(self, start: int, steps: int, file=None, interval: float = 1.0):
        self.bar = tqdm.tqdm(total=steps, initial=start, unit="step", file=file,
                             dynamic_ncols=True, mininterval=interval)
        self.bar.set_postfix_str("compiling the first step", refresh=False)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, args=(interval,), daemon=True)
        self._thread.start()

    def _tick(self, interval: float) -> None:
        """Timer thread: redraw (elapsed time, ETA) every `interval` seconds until closed."""
        while not self._stop.wait(interval):
            self.bar.refresh()

    def step(self, loss: float) -> None:
        """One step done with this loss."""
        self.bar.set_postfix(loss=f"{loss:.4f}", refresh=False)
        self.bar.update(1)

    def write(self, log, message: str) -> None:
        """`log(message)` with the bar cleared first and redrawn after."""
        with tqdm.tqdm.external_write_mode():
            log(message)

    def close(self) -> None:
        """Stop the timer and close the bar (its last state stays on screen)."""
        self._stop.set()
        self._thread.join()
        self.bar.close()


RUN_FILES = ("scene.ply", "optimizer.npz", "checkpoint.json", "metrics.jsonl", "result.json")


def _run_files(out: str) -> list[str]:
    """The files a run wrote into `out`: RUN_FILES and the held-out renders."""
    return [n for n in os.listdir(out) if n in RUN_FILES or re.fullmatch(r"heldout_r_\d+\.png", n)]


def run_dir_problem(out: str, resume: bool = False, overwrite: bool = False) -> str | None:
    """Why the run directory `out` cannot take this run, or None if it can.

    A new or empty directory always can; one holding files needs `resume` (and a checkpoint to
    resume from) or `overwrite` (its previous run's files are deleted), so two runs never mix.
    """
    if resume and overwrite:
        return "resume and overwrite exclude each other"
    if os.path.exists(out) and not os.path.isdir(out):
        return f"{out} exists and is not a directory"
    if not os.path.isdir(out) or not os.listdir(out) or overwrite:
        return None
    if resume:
        if os.path.exists(os.path.join(out, "checkpoint.json")):
            return None
        return f"{out} holds files but no checkpoint.json to resume from"
    return (f"{out} is not empty (it holds {', '.join(sorted(os.listdir(out))[:3])}, ...); "
            "pass --resume (resume=True) to continue its run or --overwrite (overwrite=True) "
            "to replace it")


def _save(out, step, params, opt_state, capacity):
    save_ply(os.path.join(out, "scene.ply"), _join(params))
    leaves = jax.tree.leaves(opt_state)
    np.savez(os.path.join(out, "optimizer.npz"), *[np.asarray(x) for x in leaves])
    json.dump(dict(step=step, capacity=capacity), open(os.path.join(out, "checkpoint.json"), "w"))


def _restore(out, opt_state):
    meta = json.load(open(os.path.join(out, "checkpoint.json")))
    params = _split(jax.tree.map(jnp.asarray, load_ply(os.path.join(out, "scene.ply"))))
    saved = np.load(os.path.join(out, "optimizer.npz"))
    leaves = [saved[f"arr_{i}"] for i in range(len(saved.files))]
    return meta, params, jax.tree.unflatten(jax.tree.structure(opt_state), leaves)


def evaluate(g: Gaussians, cams, images, background, capacity, out_dir=None, ids=None,
             backend="reference"):
    """Mean PSNR and SSIM (scikit-image) over views; renders saved as PNG when out_dir is set."""
    import matplotlib.image
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    psnrs, ssims = [], []
    for i, (cam, target) in enumerate(zip(cams, images)):
        img = np.clip(np.asarray(render(g, cam, background=background, backend=backend,
                                        capacity=capacity).image), 0, 1)
        psnrs.append(peak_signal_noise_ratio(target, img, data_range=1.0))
        ssims.append(structural_similarity(target, img, channel_axis=-1, data_range=1.0))
        if out_dir:
            matplotlib.image.imsave(os.path.join(out_dir, f"heldout_r_{ids[i]}.png"), img)
    return float(np.mean(psnrs)), float(np.mean(ssims))


@dataclasses.dataclass
class _Views:
    """A NeRF-synthetic folder split for training: cameras, images (N, H, W, 3), image ids,
    the training and held-out indices, and the scene extent (camera distance from their mean)."""

    cams: list
    images: np.ndarray
    ids: np.ndarray
    train_idx: np.ndarray
    test_idx: np.ndarray
    extent: float


def _load_views(data: str, crop) -> _Views:
    """Load `data` (ids 0, 10, ..., 90 held out), cropped to `crop` = (x0, y0, w, h) if given."""
    cams, images, ids = load_nerf(data)
    if crop:
        x0, y0, w, h = crop
        if min(crop) < 0 or w < 1 or h < 1 or x0 + w > cams[0].width or y0 + h > cams[0].height:
            raise ValueError(f"crop: {tuple(crop)} is not a non-empty window (x0, y0, w, h) of "
                             f"the {cams[0].width}x{cams[0].height} images")
        cams = [c.cropped(x0, y0, w, h) for c in cams]
        images = images[:, y0:y0 + h, x0:x0 + w]
    held = (ids % 10 == 0) & (ids <= 90)
    if held.all() or not held.any():
        raise ValueError(f"data: {data} needs training views and held-out views (ids 0, 10, "
                         f"..., 90); it has {int(held.sum())} held-out of {len(ids)}")
    centers = np.stack([np.linalg.inv(np.asarray(c.viewmat))[:3, 3] for c in cams])
    extent = float(np.linalg.norm(centers - centers.mean(0), axis=1).max())
    return _Views(cams, images, ids, np.flatnonzero(~held), np.flatnonzero(held), extent)


def _train_step(opt, settings: Settings, background, backend: str):
    """The jitted step (params, opt_state, cams, targets, step, capacity) -> (params, opt_state,
    loss, stats): the mean loss over the batch of views, its gradient, one optimizer update."""

    def batch_loss(params, cams, targets, step, capacity):
        g = _join(params)
        g = dataclasses.replace(g, sh=g.sh * sh_mask(step, g.sh.shape[1],
                                                   settings.sh_every)[None, :, None])

        def one(cam, target):
            o = render(g, cam, background=background, backend=backend, capacity=capacity)
            return loss_fn(o.image, target), o.stats

        losses, stats = jax.vmap(one)(cams, targets)
        return jnp.mean(losses), stats

    @functools.partial(jax.jit, static_argnames="capacity")
    def train_step(params, opt_state, cams, targets, step, capacity):
        (loss, stats), grads = jax.value_and_grad(batch_loss, has_aux=True)(
            params, cams, targets, step, capacity)
        updates, opt_state = opt.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss, stats

    return train_step


def _start(out, resume, views: _Views, opt, n_gaussians, seed, log):
    """(params, opt_state, start step, capacity): from OUT's checkpoint when resuming (and one
    exists), else random Gaussians, step 0 and a capacity twice the first view's pairs."""
    params = _split(jax.tree.map(jnp.asarray, random_init(n_gaussians, np.zeros(3), 1.3,
                                                          seed=seed)))
    opt_state = opt.init(params)
    start, capacity = 0, None
    if resume and os.path.exists(os.path.join(out, "checkpoint.json")):
        meta, params, opt_state = _restore(out, opt_state)
        start, capacity = meta["step"], meta["capacity"]
        log(f"resumed at step {start}")
    if capacity is None:
        first = views.cams[views.train_idx[0]]
        capacity = next_pow2(max(int(render(_join(params), first).stats.pairs_required), 1) * 2)
    return params, opt_state, start, capacity


def _evaluate_held_out(params, views: _Views, background, capacity, backend, out=None):
    """Held-out (PSNR, SSIM); renders written to `out` when given."""
    return evaluate(_join(params), [views.cams[i] for i in views.test_idx],
                    views.images[views.test_idx], background, capacity, out_dir=out,
                    ids=views.ids[views.test_idx] if out else None, backend=backend)


def fit(data: str, steps: int, out: str, n_gaussians: int = 20000, resume: bool = False,
        settings: Settings = Settings(), seed: int = 0, crop=None, backend: str | None = None,
        log=print, overwrite: bool = False):
    """Train on a NeRF-synthetic folder (ids 0, 10, ..., 90 held out); returns the final metrics.

    `out` must be new or empty unless `resume` (continue from its checkpoint) or `overwrite`
    (delete its previous run's files first) is set (`run_dir_problem`). `crop` = (x0, y0, w, h)
    trains and evaluates on a window of every image (for quick tests); `backend`: a
    differentiable backend ("reference", "tiles", "pallas", "pallas_vanilla"); None: "pallas"
    on GPUs, "tiles" elsewhere. Progress is a tqdm bar on stderr; `log` gets the other lines.
    The result's `ms_per_step` is the wall time of this call (compilation and evaluations
    included) per step it ran, None when it ran none.
    """
    _check_fit_args(steps, n_gaussians, settings)
    problem = run_dir_problem(out, resume, overwrite)
    if problem:
        raise ValueError(f"out: {problem}")
    if backend is None:
        backend = "pallas" if jax.default_backend() == "gpu" else "tiles"
    views = _load_views(data, crop)  # before touching `out`: a bad folder deletes nothing
    if settings.batch > len(views.train_idx):
        raise ValueError(f"settings.batch: {settings.batch} views per step, but {data} has "
                         f"{len(views.train_idx)} training views")
    if overwrite and os.path.isdir(out):
        for name in _run_files(out):
            os.remove(os.path.join(out, name))
    os.makedirs(out, exist_ok=True)
    bg = jnp.ones(3, jnp.float32)
    opt = optimizer(steps, views.extent, settings)
    params, opt_state, start, capacity = _start(out, resume, views, opt, n_gaussians, seed, log)
    t0 = time.perf_counter()
    params, capacity = _train(out, steps, start, params, opt_state, capacity, views, settings,
                              _train_step(opt, settings, bg, backend), seed, log,
                              lambda p, c: _evaluate_held_out(p, views, bg, c, backend))
    psnr, ssim_v = _evaluate_held_out(params, views, bg, capacity, backend, out=out)
    with open(os.path.join(out, "metrics.jsonl"), "a") as f:
        f.write(json.dumps(dict(step=max(start, steps), heldout_psnr=psnr,
                                heldout_ssim=ssim_v)) + "\n")
    log(f"step {max(start, steps)}: held-out PSNR {psnr:.2f} dB, SSIM {ssim_v:.4f}")
    seconds = time.perf_counter() - t0
    ran = max(steps - start, 0)
    result = dict(steps=steps, heldout_psnr=psnr, heldout_ssim=ssim_v, seconds=seconds,
                  ms_per_step=1e3 * seconds / ran if ran else None, gaussians=n_gaussians,
                  backend=backend, device=jax.devices()[0].device_kind)
    with open(os.path.join(out, "result.json"), "w") as f:
        json.dump(result, f, indent=1)
    return result


def _check_fit_args(steps, n_gaussians, settings: Settings) -> None:
    """Raise `ValueError` naming the argument for counts `fit` cannot use."""
    for name, v, low in (("steps", steps, 0), ("n_gaussians", n_gaussians, 1),
                         ("settings.batch", settings.batch, 1),
                         ("settings.eval_every", settings.eval_every, 1),
                         ("settings.checkpoint_every", settings.checkpoint_every, 1),
                         ("settings.sh_every", settings.sh_every, 1)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < low:
            raise ValueError(f"{name}: expected an int >= {low}, got {v!r}")


def _train(out, steps, start, params, opt_state, capacity, views: _Views, settings: Settings,
           train_step, seed, log, evaluate_fn):
    """The loop from `start` to `steps`: random batches of training views, capacity grown
    whenever a batch overflows (recompile and redo the step: nothing dropped), metrics appended
    to OUT/metrics.jsonl, held-out evaluation every `eval_every` steps (not the last), a
    checkpoint every `checkpoint_every` steps and at the end. Returns (params, capacity)."""
    rng = np.random.default_rng(seed + start)
    progress = _Progress(start, steps)
    t0 = time.perf_counter()
    step = start
    try:
        with open(os.path.join(out, "metrics.jsonl"), "a", buffering=1) as log_file:
            record = lambda **row: log_file.write(json.dumps(row) + "\n")
            while step < steps:
                pick = rng.choice(views.train_idx, settings.batch, replace=False)
                batch_cams = stack_cameras([views.cams[i] for i in pick])
                new = train_step(params, opt_state, batch_cams, jnp.asarray(views.images[pick]),
                                 step, capacity=capacity)
                if bool(np.any(np.asarray(new[3].overflow))):
                    capacity = next_pow2(int(np.max(np.asarray(new[3].pairs_required))))
                    progress.write(log, f"capacity grown to {capacity}")
                    continue
                params, opt_state, loss = new[0], new[1], float(new[2])
                step += 1
                record(step=step, loss=loss, seconds=time.perf_counter() - t0)
                progress.step(loss)
                if step % settings.eval_every == 0 and step < steps:  # the last step's: in fit
                    psnr, ssim_v = evaluate_fn(params, capacity)
                    record(step=step, heldout_psnr=psnr, heldout_ssim=ssim_v)
                    progress.write(log, f"step {step}: held-out PSNR {psnr:.2f} dB, "
                                        f"SSIM {ssim_v:.4f}")
                if step % settings.checkpoint_every == 0 or step == steps:
                    _save(out, step, params, opt_state, capacity)
    finally:
        progress.close()
    return params, capacity
