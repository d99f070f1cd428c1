"""A step's metrics reach the host through one packed vector (`step.packed`,
`step.read_metrics`): every value bit for bit, whatever its dtype (bool, int32, int64, float32,
float64: non-finite values and their payloads included), scalars as Python scalars of the
type `.item()` gives, arrays as numpy arrays."""

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, strategies as st

from lgs_jax.train.step import packed, read_metrics

_PACK = jax.jit(lambda m: dict(m, packed=packed(m)))  # one program: values are its arguments

FLOAT32 = st.floats(width=32, allow_nan=True, allow_infinity=True)


@given(loss=FLOAT32, psnr=st.floats(allow_nan=True, allow_infinity=True),
       flag=st.booleans(), pairs=st.integers(-2**31, 2**31 - 1),
       count=st.integers(-2**63, 2**63 - 1),
       per=st.lists(FLOAT32, min_size=3, max_size=3))
def test_metrics_read_back_bit_for_bit(loss, psnr, flag, pairs, count, per):
    metrics = dict(loss=jnp.float32(loss), psnr=jnp.float64(psnr), ok=jnp.bool_(flag),
                   overflow=jnp.bool_(not flag), pairs=jnp.int32(pairs), count=jnp.int64(count),
                   per_device=jnp.asarray(per, jnp.float32))
    on_device = _PACK(metrics)
    got = read_metrics(on_device)
    assert set(got) == set(metrics)
    for name, x in metrics.items():
        want = np.asarray(on_device[name])
        assert np.asarray(got[name], want.dtype).tobytes() == want.tobytes(), name
        if want.size == 1:
            assert type(got[name]) is type(on_device[name].item()), name
        else:
            assert isinstance(got[name], np.ndarray) and got[name].shape == want.shape
