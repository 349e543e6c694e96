"""Strict, fast test settings shared by every test file (STYLE §9)."""

import os

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

from hypothesis import settings  # noqa: E402

settings.register_profile("deltajax", deadline=None, max_examples=25, derandomize=True)
settings.load_profile("deltajax")
