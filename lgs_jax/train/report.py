"""What a run shows and writes: the progress bar, metrics, held-out renders, the curves figure."""

from __future__ import annotations

import concurrent.futures
import contextlib
import json
import os
import threading
import time

import jax
import numpy as np
import tqdm

from ..files import written
from . import processes


class _Bar(tqdm.tqdm):
    """tqdm whose rate (and so ETA) is `step_rate` where set: the steps' own, compiles left
    out."""

    step_rate = None

    @property
    def format_dict(self):
        d = super().format_dict
        if self.step_rate:
            d["rate"] = self.step_rate
        return d


class Progress:
    """A tqdm progress bar on stderr (step, loss, training PSNR, Gaussian count, rate, ETA),
    redrawn every `interval` seconds, also while one step runs (the first step compiles, for
    a minute or more on a CPU). Its rate and ETA are the steps' own (`step`'s `rate`), from
    the first step on: the time spent compiling is not spread over the steps to come."""

    def __init__(self, start: int, steps: int, file=None, interval: float = 1.0):
        self.bar = _Bar(total=steps, initial=start, unit="step", file=file,
                        dynamic_ncols=True, mininterval=interval)
        self.bar.set_postfix_str("compiling the first step", refresh=False)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, args=(interval,), daemon=True)
        self._thread.start()

    def _tick(self, interval: float) -> None:
        """Timer thread: redraw (elapsed time, ETA) every `interval` seconds until closed."""
        while not self._stop.wait(interval):
            self.bar.refresh()

    def step(self, loss: float, psnr: float | None = None, count: int | None = None,
             rate: float | None = None) -> None:
        """One step done with this loss (and training-view PSNR, active Gaussians; `rate`:
        steps per second so far, compiles left out)."""
        post = dict(loss=f"{loss:.4f}")
        if psnr is not None:
            post["psnr"] = f"{psnr:.2f}"
        if count is not None:
            post["gaussians"] = str(count)
        self.bar.step_rate = rate
        self.bar.set_postfix(post, refresh=False)
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


# JAX's monitoring events of a compile, by the part of it they time (`CompileClock`): the trace
# to a jaxpr, its lowering to an MLIR module, and XLA's compile (or the persistent cache's load)
COMPILE_EVENTS = {"/jax/core/compile/jaxpr_trace_duration": "trace",
                  "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
                  "/jax/core/compile/backend_compile_duration": "backend"}
CACHE_HIT = "/jax/compilation_cache/cache_hits"  # a program loaded from the persistent cache
PARTS = ("trace", "lower", "backend", "waited")


def _exclusive(spans: list[tuple]) -> dict:
    """Seconds per kind of `spans` ((start, end, kind) each; spans nest or are disjoint, as one
    thread's compile events do): each instant counted once, for the innermost span over it
    (the one begun last)."""
    parts = dict.fromkeys(PARTS, 0.0)
    bounds = sorted({t for start, end, _ in spans for t in (start, end)})
    ordered, active, i = sorted(spans), [], 0
    for a, b in zip(bounds, bounds[1:]):
        while i < len(ordered) and ordered[i][0] <= a:
            active.append(ordered[i])
            i += 1
        active = [span for span in active if span[1] > a]
        if active:
            parts[max(active, key=lambda span: (span[0], -span[1]))[2]] += b - a
    return parts


class CompileClock:
    """Seconds JAX spends compiling (its "/jax/core/compile/" monitoring events: tracing,
    lowering, XLA's compile or the persistent cache's load) inside `with clock:` blocks, in the
    thread that entered them (compiles in other threads do not hold the run up), plus the
    waits for such compiles (`waited`); overlaps counted once. Use it as a context manager
    around the whole run too: `clock.listening()`.

    `parts`: those seconds by what they were spent on (trace, lower, backend: XLA's compile or
    the cache's load, waited), each instant counted once for the innermost event, so that the
    parts sum to `seconds`; `programs`: the programs compiled (by XLA) and loaded (from the
    persistent cache) in those blocks; `ahead_seconds`: the compiles of other threads while
    listening (compiles ahead), overlaps counted once."""

    def __init__(self):
        self._spans, self._ahead, self._on, self._thread = [], [], False, None
        self._backend, self._loaded = 0, 0  # backend events, and cache hits among them

    def _listen(self, event, start, end, **_):
        kind = COMPILE_EVENTS.get(event)
        if kind is None:
            return
        if threading.get_ident() != self._thread:
            self._ahead.append((start, end, kind))
        elif self._on:
            self._spans.append((start, end, kind))
            self._backend += kind == "backend"

    def _hit(self, event, **_):
        if event == CACHE_HIT and self._on and threading.get_ident() == self._thread:
            self._loaded += 1

    def waited(self, seconds: float) -> None:
        """Count `seconds` just spent waiting for a compile in another thread."""
        if self._on and seconds > 0:
            end = time.time()
            self._spans.append((end - seconds, end, "waited"))

    @contextlib.contextmanager
    def listening(self):
        """Registers the clock's listeners with JAX for the `with` block (entered in the
        thread that will enter the clock)."""
        self._thread = threading.get_ident()
        jax.monitoring.register_event_time_span_listener(self._listen)
        jax.monitoring.register_event_listener(self._hit)
        try:
            yield self
        finally:
            jax.monitoring.unregister_event_time_span_listener(self._listen)
            jax.monitoring.unregister_event_listener(self._hit)

    def __enter__(self):
        self._on, self._thread = True, threading.get_ident()
        return self

    def __exit__(self, *exc):
        self._on = False

    @property
    def parts(self) -> dict:
        return _exclusive(self._spans)

    @property
    def seconds(self) -> float:
        return sum(self.parts.values())

    @property
    def programs(self) -> dict:
        return dict(compiled=self._backend - self._loaded, loaded=self._loaded)

    @property
    def ahead_seconds(self) -> float:
        return _exclusive([(start, end, "backend") for start, end, _ in self._ahead])["backend"]

    def result(self) -> dict:
        """The clock's numbers as `fit`'s result holds them: compile_seconds, compile_parts,
        programs_compiled, programs_loaded, ahead_compile_seconds."""
        parts, programs = self.parts, self.programs
        return dict(compile_seconds=sum(parts.values()), compile_parts=parts,
                    programs_compiled=programs["compiled"], programs_loaded=programs["loaded"],
                    ahead_compile_seconds=self.ahead_seconds)


def device_memory() -> dict:
    """{mib_in_use, peak_mib}: the local devices' bytes in use now and their peak since the
    process started (the allocator's `memory_stats`, MiB; the largest device's where there
    are several), or {} where the backend keeps no such statistics (the CPU)."""
    stats = [d.memory_stats() or {} for d in jax.local_devices()]
    if not any("peak_bytes_in_use" in s for s in stats):
        return {}
    return dict(mib_in_use=round(max(s.get("bytes_in_use", 0) for s in stats) / 2**20, 1),
                peak_mib=round(max(s.get("peak_bytes_in_use", 0) for s in stats) / 2**20, 1))


class PeakRise:
    """The device's peak memory for a run's step rows: a call gives {peak_mib} where the peak
    (`device_memory`) rose by `least` MiB or more since the last it gave, else {} (always {}
    where the backend keeps no statistics: the CPU); the rows so mark the steps that raised
    it."""

    def __init__(self, least: float = 1.0):
        self.least, self.last = least, 0.0

    def __call__(self) -> dict:
        peak = device_memory().get("peak_mib")
        if peak is None or peak < self.last + self.least:
            return {}
        self.last = peak
        return dict(peak_mib=peak)


def _bytes_on(device, arrays) -> int:
    """The bytes `arrays` (jax.Arrays; other leaves ignored) hold on `device`: one shard
    (`Sharding.shard_shape`) of each array placed there."""
    total = 0
    for x in arrays:
        if isinstance(x, jax.Array) and not x.is_deleted() and device in x.sharding.device_set:
            shard = x.sharding.shard_shape(x.shape)
            total += int(np.prod(shard)) * (x.nbytes // max(x.size, 1))
    return total


def memory_parts(parts: dict, temporaries: float | None = None) -> dict:
    """Device memory by part, MiB to the KiB, on this process's first device: each tree of
    `parts` (its arrays' shards there), other_arrays (the live arrays in none of them: training
    views in flight, held-out targets, ...) with the largest three ([shape and dtype, MiB]),
    the step program's XLA `temporaries` where given, and `device_memory`'s in use and peak
    (in use beyond the arrays: executables' constants, buffers freed late)."""
    device = jax.local_devices()[0]
    mib = lambda n: round(n / 2**20, 3)
    held = {id(x) for tree in parts.values() for x in jax.tree.leaves(tree)}
    others = [x for x in jax.live_arrays() if id(x) not in held]
    sizes = sorted(((_bytes_on(device, [x]), f"{x.shape} {x.dtype}") for x in others),
                   reverse=True)
    out = {f"{name}_mib": mib(_bytes_on(device, jax.tree.leaves(tree)))
           for name, tree in parts.items()}
    out.update(other_arrays_mib=mib(sum(n for n, _ in sizes)),
               largest_other=[[what, mib(n)] for n, what in sizes[:3] if n])
    if temporaries is not None:
        out["step_temporaries_mib"] = round(temporaries, 3)
    return dict(out, **device_memory())


def _threads(fn, *lists) -> list:
    """[fn(*items) for items in zip(*lists)] on a few threads (numpy, scikit-image and PNG
    compression release Python's lock in their loops), in order."""
    with concurrent.futures.ThreadPoolExecutor(min(8, os.cpu_count() or 1)) as pool:
        return list(pool.map(fn, *lists))


def view_metrics(images, targets) -> list[tuple[float, float]]:
    """(PSNR, SSIM) of each view with scikit-image's defaults (data range 1; SSIM with its 7x7
    uniform window, per channel)."""
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    return _threads(lambda i, t: (float(peak_signal_noise_ratio(t, i, data_range=1.0)),
                                  float(structural_similarity(t, i, channel_axis=-1,
                                                              data_range=1.0))),
                    images, targets)


def heldout_metrics(images, targets) -> tuple[float, float]:
    """Mean PSNR and SSIM over views (`view_metrics`)."""
    scores = view_metrics(images, targets)
    return float(np.mean([p for p, _ in scores])), float(np.mean([s for _, s in scores]))


def save_renders(out: str, images, targets, names, prefix: str = "heldout") -> None:
    """<prefix>_<name>.png: each render (left) beside its ground truth (right), 8-bit RGB
    (values in [0, 1] rounded to the nearest of 256), PNG's fastest compression."""
    from PIL import Image

    def one(image, target, name):
        side = np.concatenate([np.clip(image, 0, 1), np.clip(target, 0, 1)], 1)
        with written(os.path.join(out, f"{prefix}_{name}.png")) as tmp:
            Image.fromarray(np.rint(side * 255).astype(np.uint8)).save(tmp, format="PNG",
                                                                       compress_level=1)
    _threads(one, images, targets, names)


@contextlib.contextmanager
def metrics_rows(out: str):
    """A function that writes its keyword arguments as a row of OUT/metrics.jsonl (a JSON line,
    appended, line-buffered); one that writes nothing on a process that does not write the
    run folder (`processes.writer`)."""
    if not processes.writer():
        yield lambda **row: None
        return
    with open(os.path.join(out, "metrics.jsonl"), "a", buffering=1) as f:
        yield lambda **row: f.write(json.dumps(row) + "\n")


def read_metrics(path: str) -> list[dict]:
    """The rows of a metrics.jsonl; a last line without its newline (a write cut short by a
    kill) is left out, any other line that is not JSON raises `ValueError` naming it."""
    with open(path) as f:
        lines = f.readlines()
    if lines and not lines[-1].endswith("\n"):
        lines.pop()
    rows = []
    for number, line in enumerate(lines, 1):
        if line.strip():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError as e:
                raise ValueError(f"{path}: line {number} is not JSON ({e.msg})") from None
    return rows


def plot_curves(rows: list[dict], path: str) -> None:
    """A 2x2 figure of the run: loss, PSNR (training views and held-out), held-out SSIM, and
    the number of Gaussians, against the step."""
    from matplotlib.figure import Figure  # no pyplot: leaves the caller's backend alone

    def series(key):
        pts = [(r["step"], r[key]) for r in rows if "step" in r and r.get(key) is not None]
        return ([p[0] for p in pts], [p[1] for p in pts])

    fig = Figure(figsize=(10, 7))
    ax = fig.subplots(2, 2)
    steps, losses = series("loss")
    ax[0, 0].plot(steps, losses, lw=0.5)
    ax[0, 0].set(title="loss", xlabel="step",
                 yscale="log" if any(v > 0 for v in losses) else "linear")
    ax[0, 1].plot(*series("psnr"), lw=0.5, alpha=0.5, label="training view")
    ax[0, 1].plot(*series("heldout_psnr"), "o-", label="held-out")
    ax[0, 1].set(title="PSNR (dB)", xlabel="step")
    ax[0, 1].legend()
    ax[1, 0].plot(*series("heldout_ssim"), "o-")
    ax[1, 0].set(title="held-out SSIM", xlabel="step")
    ax[1, 1].plot(*series("gaussians"))
    ax[1, 1].set(title="Gaussians", xlabel="step")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
