"""Float64 by default, and the package's XLA settings once JAX is loaded.

Importing :mod:`tension_zones` turns on ``jax_enable_x64`` (analysis wants float64: pinv, small
singular values and 1e-9 agreement need it). Set ``TENSION_ZONES_X64=0`` in the environment before
importing to leave JAX's setting alone; float32 designs (``Design.astype(jnp.float32)``) work either way.

The package itself does not import JAX (``tension_zones/__init__.py`` is lazy): if JAX is not loaded
yet it sets JAX's own switch ``JAX_ENABLE_X64=1`` in the environment (unless already set), which JAX
reads when it is imported (child processes inherit it); this module, imported by every sub-package
that uses JAX, sets the flag directly in case JAX was imported first.

This module also applies :func:`tension_zones._xla.apply_settings` (XLA's concurrency-optimised CPU
scheduler off, the persistent compilation cache; see :mod:`tension_zones._xla`, which says how to
switch each off). XLA reads ``XLA_FLAGS`` when JAX makes its first array, so use a sub-package of
``tension_zones`` (``tz.Design``, ``tension_zones.model``, ...) before computing anything with JAX.
"""

import os

import jax

from ._xla import apply_settings

if os.environ.get("TENSION_ZONES_X64", "1").strip().lower() not in ("0", "false", "no", "off"):
    jax.config.update("jax_enable_x64", True)
apply_settings()
