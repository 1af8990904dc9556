"""Float64 by default.

Importing :mod:`tension_zones` turns on ``jax_enable_x64`` (analysis wants float64: pinv, small
singular values and 1e-9 agreement need it). Set ``TENSION_ZONES_X64=0`` in the environment before
importing to leave JAX's setting alone; float32 designs (``Design.astype(jnp.float32)``) work either way.

The package itself does not import JAX (``tension_zones/__init__.py`` is lazy): if JAX is not loaded
yet it sets JAX's own switch ``JAX_ENABLE_X64=1`` in the environment (unless already set), which JAX
reads when it is imported (child processes inherit it); this module, imported by every sub-package
that uses JAX, sets the flag directly in case JAX was imported first.

**XLA's CPU scheduler.** XLA's concurrency-optimised CPU scheduler can leave a computation waiting
forever on this package's large vmapped while loops (seen on 2 cores: the rod model of a
three-segment robot over 1000 samples hung with every thread idle; 5 s with the flag off). So the
package adds ``--xla_cpu_enable_concurrency_optimized_scheduler=false`` to ``XLA_FLAGS`` unless
that flag is already there; XLA reads it when JAX makes its first array, so import
``tension_zones`` before computing anything with JAX.

**Compilation cache.** Compiled programs, and the calibration's exported programs, are kept on disk
(see :mod:`._xla`); set ``TENSION_ZONES_CACHE=0`` to turn that off. Deleting the folder is safe: it
only costs the next run its compile.
"""

import os

import jax

from ._xla import cache_dir, with_scheduler_off

if os.environ.get("TENSION_ZONES_X64", "1").strip().lower() not in ("0", "false", "no", "off"):
    jax.config.update("jax_enable_x64", True)
os.environ["XLA_FLAGS"] = with_scheduler_off(os.environ.get("XLA_FLAGS", ""))
_mine = jax.config.jax_compilation_cache_dir is None and "JAX_COMPILATION_CACHE_DIR" not in os.environ
if _mine and (_path := cache_dir()):
    jax.config.update("jax_compilation_cache_dir", _path)
