"""The one-time float32 warning (host side).

JAX computes in float32 unless ``jax_enable_x64`` is on. deltajax does not flip that global switch at import
(STYLE §6), so a user who forgets it silently gets float32 results, 0.5-1.6 % off near singular points.
:func:`warn_if_float32` warns once per process when a robot is built or an analysis runs with float32 arrays
and nobody asked for float32 (the CLI's ``precision=float32`` asks; so does
``warnings.simplefilter("ignore", deltajax.Float32Warning)``).
"""

from __future__ import annotations

import warnings

__all__ = ["Float32Warning", "warn_if_float32", "float32_requested"]


class Float32Warning(UserWarning):
    """Analysis running in float32 because ``jax_enable_x64`` is off (see :func:`warn_if_float32`)."""


_state = {"warned": False, "requested": False}


def float32_requested(flag: bool = True) -> None:
    """Record that float32 is the caller's choice (no warning), e.g. the CLI's ``precision=float32``."""
    _state["requested"] = bool(flag)


def warn_if_float32(dtype, where: str = "deltajax") -> bool:
    """Warn (once per process) when ``dtype`` is float32 and float32 was not requested.

    Returns:
        True if this call warned.
    """
    import numpy as np

    if _state["warned"] or _state["requested"] or np.dtype(dtype) != np.float32:
        return False
    _state["warned"] = True
    warnings.warn(
        f"{where} runs in float32 because jax_enable_x64 is off: results are 0.5-1.6 % off near singular "
        "points. Call jax.config.update('jax_enable_x64', True) before building robots (the CLI does it for "
        "precision=float64), or silence this with warnings.simplefilter('ignore', deltajax.Float32Warning) "
        "if float32 is what you want.", Float32Warning, stacklevel=3)
    return True
