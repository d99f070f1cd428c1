"""What a run reports of the device: the steps that raised its peak memory (`PeakRise`), its
memory by part (`memory_parts`), and how long the steps waited for it (`outputs.time_parts`)."""

import jax.numpy as jnp
import numpy as np

from lgs_jax.train import report


def test_a_step_row_carries_the_peak_where_it_rose_by_a_mib(monkeypatch):
    peaks = iter([100.0, 100.5, 101.0, 101.0, 250.2])
    monkeypatch.setattr(report, "device_memory", lambda: dict(mib_in_use=1.0,
                                                              peak_mib=next(peaks)))
    rise = report.PeakRise()
    assert [rise() for _ in range(5)] == [dict(peak_mib=100.0), {}, dict(peak_mib=101.0), {},
                                          dict(peak_mib=250.2)]
    monkeypatch.setattr(report, "device_memory", lambda: {})  # the CPU: no statistics
    assert report.PeakRise()() == {}


def test_memory_by_part_counts_each_part_and_names_the_largest_other_arrays():
    pool = dict(means=jnp.zeros((1024, 3), jnp.float32), active=jnp.zeros(1024, bool))
    opt = (jnp.zeros((1024, 3), jnp.float32), jnp.zeros((1024, 3), jnp.float32),
           jnp.zeros((), jnp.int32))
    other = jnp.ones((512, 512, 3), jnp.uint8)  # held by no part
    deleted = jnp.ones((2048, 3), jnp.float32)
    deleted.delete()
    parts = report.memory_parts(dict(pool=pool, optimizer=opt, views=None), temporaries=2.5)
    mib = lambda n: round(n / 2**20, 3)
    assert parts["pool_mib"] == mib(1024 * 13) and parts["optimizer_mib"] == mib(1024 * 24 + 4)
    assert parts["views_mib"] == 0 and parts["step_temporaries_mib"] == 2.5
    assert parts["largest_other"][0] == ["(512, 512, 3) uint8", mib(other.nbytes)]
    assert parts["other_arrays_mib"] >= mib(other.nbytes)
    assert np.asarray(other).sum() > 0  # alive until here


def test_the_closing_line_says_how_long_the_steps_waited_for_the_device():
    from lgs_jax.train.outputs import time_parts

    run = dict(seconds=10.0, load_seconds=1.0, step_seconds=8.0, compile_seconds=2.0,
               device_wait_seconds=5.0, eval_seconds=0.5, checkpoint_seconds=0.1,
               finish_seconds=0.4)
    assert time_parts(run) == ("10.0 s in all: loading and starting 1.0 s, steps 8.0 s "
                               "(compiling 2.0 s; waiting for the device 5.0 s), held-out "
                               "evaluations 0.5 s, checkpoints 0.1 s, final evaluation and "
                               "outputs 0.4 s")
