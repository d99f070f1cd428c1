"""lgs_jax.train.ahead's mode "process": the step for the next capacity compiled in a child
process lands in the persistent compilation cache under the key this process looks up (a cache
hit at the growth, from a cache that was empty); the thread mode's switch interval; compiles
ahead on one device only; `fit`'s compile_ahead is checked."""

import functools
import sys
import threading

import jax
import jax.numpy as jnp
import pytest
from jax._src import compilation_cache

from lgs_jax.train import ahead


@functools.partial(jax.jit, static_argnames="capacity")
def _scaled(x, capacity):  # module level: the child process imports it
    return jnp.cumsum(jnp.sin(x) * capacity)


def _static(size):
    return dict(capacity=size[0])


def _scaled_rows(x, capacity, rows):
    return jnp.cumsum(jnp.sin(x) * capacity) + rows


def _static_rows(size):
    return dict(capacity=size[0], rows=size[1])


@pytest.fixture
def empty_cache(tmp_path):
    """A persistent compilation cache of its own, empty, caching every compile; the suite's
    cache back afterwards."""
    names = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs")
    before = {name: jax.config.values[name] for name in names}
    jax.config.update("jax_compilation_cache_dir", str(tmp_path / "cache"))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    compilation_cache.reset_cache()
    yield tmp_path / "cache"
    for name, value in before.items():
        jax.config.update(name, value)
    compilation_cache.reset_cache()


def test_a_child_compile_is_the_growths_cache_hit(empty_cache):
    stepper = ahead.Stepper(_scaled, _static, ahead.Sizes(1.5), "process")
    args = (jnp.linspace(0, 1, 5),)
    sig = ahead.signature(args)
    first = stepper.run(args, (1024, None), sig)
    stepper.prepare(args, (1024, None), sig)  # pair_capacity(1025, 1.5) = 2048, in a child
    capacity, waited, taken = stepper.grow((1024, None), (1100, 0), sig)
    assert (capacity, taken) == ((2048, None), True) and waited >= 0
    events = []
    listen = lambda event, **_: events.append(event)
    jax.monitoring.register_event_listener(listen)
    try:
        grown = stepper.run(args, capacity, sig)
    finally:
        jax.monitoring.unregister_event_listener(listen)
    stepper.close()
    assert "/jax/compilation_cache/cache_hits" in events, events
    assert jnp.array_equal(grown, first * 2)


def test_a_failed_child_costs_only_the_compile(empty_cache):
    """A jitted function the child cannot import (a lambda): the growth compiles in this
    process."""
    local = jax.jit(lambda x, capacity: _scaled(x, capacity=capacity),
                    static_argnames="capacity")
    stepper = ahead.Stepper(local, _static, ahead.Sizes(1.5), "process")
    # another shape than the cache-hit test's: its compile of _scaled must not be in memory
    args = (jnp.linspace(0, 1, 6),)
    sig = ahead.signature(args)
    stepper.run(args, (1024, None), sig)
    stepper.prepare(args, (1024, None), sig)
    capacity, _, taken = stepper.grow((1024, None), (1100, 0), sig)
    assert capacity == (2048, None) and not taken
    assert "<lambda>: not a module-level function" in stepper.failure  # the child's reason
    assert jnp.array_equal(stepper.run(args, capacity, sig), _scaled(args[0], capacity=2048))
    stepper.close()


@pytest.mark.parametrize("value,want", [("off", None), ("thread", "thread"),
                                        ("process", "process"), (None, "default")])
def test_compile_ahead_modes(value, want):
    """None means a compile thread on a GPU and none on a CPU; "process" with the suite's cache
    on."""
    if want == "default":
        want = "thread" if jax.default_backend() == "gpu" else None
    assert ahead.mode_of(value) == want


@pytest.mark.parametrize("value", ["threads", 1, True])
def test_bad_compile_ahead_raises(value):
    with pytest.raises(ValueError, match="compile_ahead"):
        ahead.mode_of(value)


def test_process_mode_without_the_cache_raises():
    before = jax.config.values["jax_compilation_cache_dir"]
    jax.config.update("jax_compilation_cache_dir", None)
    try:
        with pytest.raises(ValueError, match="persistent compilation cache"):
            ahead.mode_of("process")
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


class _Traced:
    """A stand-in for a jitted function whose lowering records Python's switch interval."""

    def __init__(self):
        self.intervals = []

    def __call__(self, *args, capacity):
        return ("jit", capacity)

    def lower(self, *args, capacity):
        self.intervals.append(sys.getswitchinterval())
        return self

    def compile(self):
        return lambda *args: "executable"


def test_a_thread_compiling_ahead_switches_often_and_restores_the_interval():
    """Mode "thread": while the compile ahead traces, Python's switch interval is
    `ahead.SWITCH_INTERVAL` (the loop's thread gets the lock back promptly after each wait on
    the device); the interval before is restored once it is done."""
    before = sys.getswitchinterval()
    fn = _Traced()
    stepper = ahead.Stepper(fn, _static, ahead.Sizes(1.5), "thread")
    args = (jnp.zeros(3),)
    sig = ahead.signature(args)
    stepper.prepare(args, (1024, None), sig)
    size, _, taken = stepper.grow((1024, None), (1025, 0), sig)
    assert taken and stepper.run(args, size, sig) == "executable"
    assert fn.intervals == [pytest.approx(ahead.SWITCH_INTERVAL)]
    assert before > 2 * ahead.SWITCH_INTERVAL
    assert sys.getswitchinterval() == before
    stepper.close()


def test_overlapping_compiles_ahead_restore_the_interval_after_the_last():
    """Two steppers' compiles ahead under way at once (the step's and the evaluations'): the
    interval stays `SWITCH_INTERVAL` until the last ends, then the one before is back."""
    before = sys.getswitchinterval()
    started, gate, seen = threading.Event(), threading.Event(), []

    class Quick(_Traced):  # starts first, ends once the slow one has started
        def compile(self):
            started.wait(10)
            return lambda *args: "executable"

    class Slow(_Traced):
        def lower(self, *args, capacity):
            started.set()
            return self

        def compile(self):
            gate.wait(10)
            seen.append(sys.getswitchinterval())
            return lambda *args: "executable"

    slow, quick = Slow(), Quick()
    steppers = [ahead.Stepper(fn, _static, ahead.Sizes(1.5), "thread") for fn in (slow, quick)]
    args = (jnp.zeros(3),)
    sig = ahead.signature(args)
    steppers[1].prepare(args, (1024, None), sig)
    steppers[0].prepare(args, (1024, None), sig)
    assert steppers[1].grow((1024, None), (1025, 0), sig)[2]  # the quick one done first
    assert sys.getswitchinterval() == pytest.approx(ahead.SWITCH_INTERVAL)
    gate.set()
    assert steppers[0].grow((1024, None), (1025, 0), sig)[2]
    assert seen == [pytest.approx(ahead.SWITCH_INTERVAL)]
    assert sys.getswitchinterval() == before
    for s in steppers:
        s.close()


@pytest.mark.parametrize("devices,gaussian_devices,want", [(1, 1, True), (2, 1, False),
                                                           (1, 2, False)])
def test_steps_compile_ahead_on_one_device_only(devices, gaussian_devices, want):
    """`fit`'s step compiles ahead on one device only (its evaluations likewise): an executable
    compiled ahead is for arguments on one device, and a data-parallel step's are replicated
    or split over several (calling it with them raises)."""
    from lgs_jax.train import FitConfig, loop
    from lgs_jax.train.config import Setup

    config = FitConfig(data="unused", out="unused", compile_ahead="thread")
    setup = Setup(devices=devices, gaussian_devices=gaussian_devices)
    stepper = loop.stepper(config, setup)
    assert stepper.compiles_ahead == want
    stepper.close()


def test_a_size_takes_a_kept_program_a_little_above_it(tmp_path):
    """`Stepper.kept`: a size whose program is not kept becomes the smallest larger pair
    capacity, at most `REUSE` times it, whose program an earlier run exported (another seed's
    run: a load, not a compile), else the largest smaller one down to `Sizes.least` of the
    pairs it is for; a growth does the same (`took_kept`); farther away, or with no
    exports, the size stays."""
    from lgs_jax.train import exports

    x = jnp.arange(8.0)
    sig, earlier = ahead.signature((x,)), 1_310_720  # 10 x 2^17, on the pair-capacity grid
    lowering = lambda: exports.Lowering(str(tmp_path / "exports"))
    first = ahead.Stepper(_scaled, _static, ahead.Sizes(1.0), None, lowering())
    first.run((x,), (earlier, None), sig)  # exported and compiled
    stepper = ahead.Stepper(_scaled, _static, ahead.Sizes(1.0), None, lowering())
    assert stepper.kept(sig, (1_179_648, None)) == (earlier, None)  # 1.11x below: taken
    assert stepper.kept(sig, (1_048_576, None)) == (earlier, None)  # 1.25x: taken
    assert stepper.kept(sig, (983_040, None)) == (983_040, None)  # 1.33x: compiled instead
    # given the pairs, below the size down to `Sizes.least` of them (here the pairs: headroom
    # 1): the largest kept one
    assert stepper.kept(sig, (1_441_792, None), pairs=1_310_720) == (earlier, None)
    assert stepper.kept(sig, (2_097_152, None), pairs=1_048_576) == (earlier, None)
    assert stepper.kept(sig, (2_097_152, None), pairs=1_441_792) == (2_097_152, None)
    assert stepper.kept(sig, (2_097_152, None)) == (2_097_152, None)  # no pairs: none below
    assert stepper.kept(ahead.signature((jnp.arange(9.0),)), (1_179_648, None)) == (
        1_179_648, None)  # another shape: nothing kept for it
    size, waited, took_ahead = stepper.grow((983_040, None), (1_100_000, 0), sig)
    assert size == (earlier, None) and stepper.took_kept and not took_ahead
    size, _, _ = stepper.grow((earlier, None), (1_400_000, 0), sig)
    assert size == (1_441_792, None) and not stepper.took_kept  # pair_capacity(1.4M): compiled
    # a headroom of 3: 1M pairs grow to 3.1M, not to the kept 1.31M (under 1.5x the pairs);
    # 0.8M pairs take it (at least 1.2M) rather than compile 2.6M
    roomy = ahead.Stepper(_scaled, _static, ahead.Sizes(3.0), None, lowering())
    assert roomy.grow((524_288, None), (1_000_000, 0), sig)[0] == (3_145_728, None)
    assert not roomy.took_kept
    assert roomy.grow((524_288, None), (800_000, 0), sig)[0] == (earlier, None)
    assert roomy.took_kept
    plain = ahead.Stepper(_scaled, _static, ahead.Sizes(1.0), None)
    assert plain.kept(sig, (1_179_648, None)) == (1_179_648, None)


def test_a_kept_program_is_looked_for_with_the_rows_of_its_capacity(tmp_path):
    """With backward rows (`Sizes.rows_for`: a capacity comes with its rows), `Stepper.kept`
    looks for each capacity at the rows a run that grew to it has (above the size, never fewer
    than the size's); a growth takes a kept size only where its rows hold the walked pairs."""
    from lgs_jax.train import exports

    x, sizes = jnp.arange(8.0), ahead.Sizes(3.0, 1.5)
    sig, earlier = ahead.signature((x,)), 1_310_720
    rows = sizes.rows_for(earlier)  # 655,360
    lowering = lambda: exports.Lowering(str(tmp_path / "exports"))
    ahead.Stepper(_scaled_rows, _static_rows, sizes, None, lowering()).run((x,), (earlier, rows),
                                                                         sig)
    stepper = ahead.Stepper(_scaled_rows, _static_rows, sizes, None, lowering())
    size = (1_179_648, sizes.rows_for(1_179_648))
    assert stepper.kept(sig, size) == (earlier, rows)  # above, with its rows
    assert stepper.kept(sig, (1_179_648, 700_000)) == (1_179_648, 700_000)  # rows grown alone
    big = (sizes.grown((524_288, 262_144), (800_000, 0)))  # 800k pairs: 2.4M, least 1.2M
    assert stepper.kept(sig, big, pairs=800_000) == (earlier, rows)  # below, with its rows
    assert stepper.grow((524_288, 262_144), (800_000, 600_000), sig)[0] == (earlier, rows)
    assert stepper.took_kept
    assert stepper.grow((524_288, 262_144), (800_000, 700_000), sig)[0] == big  # rows short
    assert not stepper.took_kept
