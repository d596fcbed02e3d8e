"""Work run in other threads (``metriplex._threads``) runs under the caller's JAX settings."""

from concurrent.futures import ThreadPoolExecutor

import jax

from metriplex._threads import in_this_threads_config


def _settings():
    c = jax.config
    return (c.jax_enable_x64, c.jax_default_matmul_precision, c.jax_default_device,
            c.jax_numpy_dtype_promotion, c.jax_numpy_rank_promotion)


def test_a_worker_runs_under_the_callers_jax_settings():
    # JAX's context managers for these are per thread: a plain worker sees the global values
    # (here the suite's: x64 on, strict promotion), so a program it compiles could differ from
    # the caller's (another dtype, device or precision).
    with (jax.enable_x64(False), jax.default_matmul_precision("bfloat16"),
          jax.default_device(jax.devices("cpu")[0]), jax.numpy_dtype_promotion("standard"),
          jax.numpy_rank_promotion("allow")):
        here = _settings()
        carried = in_this_threads_config(_settings)
    with ThreadPoolExecutor(1) as pool:
        bare = pool.submit(_settings).result()
        inside = pool.submit(carried).result()
    assert inside == here
    assert all(a != b for a, b in zip(bare, here)), (bare, here)
