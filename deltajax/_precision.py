"""The one-time float32 warning (host side).

JAX computes in float32 unless ``jax_enable_x64`` is on. deltajax does not flip that global switch at import
(STYLE §6), so a user who forgets it silently gets float32 results, 0.5-1.6 % off near singular points.
:func:`warn_if_float32` warns once per process when a robot is built or an analysis runs with float32 arrays
and nobody asked for float32 (the CLI's ``precision=float32`` asks; so does
``warnings.simplefilter("ignore", deltajax.Float32Warning)``).
"""

from __future__ import annotations

import warnings
import os
import sys

import numpy as np

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
    if _state["warned"] or _state["requested"] or np.dtype(dtype) != np.float32:
        return False
    _state["warned"] = True
    warnings.warn(
        f"{where} runs in float32 because jax_enable_x64 is off: results are 0.5-1.6 % off near singular "
        "points. Call jax.config.update('jax_enable_x64', True) before building robots (the CLI does it for "
        "precision=float64), or silence this with warnings.simplefilter('ignore', deltajax.Float32Warning) "
        "if float32 is what you want.", Float32Warning, stacklevel=_user_stacklevel())
    return True


def _user_stacklevel() -> int:
    """The ``stacklevel`` of the first caller outside deltajax, equinox and jax, so the warning names the
    user's line (where the robot was built), not equinox's ``__check_init__`` machinery."""
    inside = tuple(os.path.dirname(m.__file__) + os.sep for m in
                   (sys.modules.get("deltajax"), sys.modules.get("equinox"), sys.modules.get("jax"))
                   if m is not None and getattr(m, "__file__", None))
    level, frame = 1, sys._getframe(1)  # 1: warn_if_float32's frame (warnings.warn counts from its caller)
    while frame is not None and frame.f_code.co_filename.startswith(inside):
        frame, level = frame.f_back, level + 1
    return level
