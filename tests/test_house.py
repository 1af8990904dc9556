"""House rules of the package: what importing it does, what its text may say, what it names."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(code, env):
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False,
                         cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip().splitlines()


def test_import_enables_float64_and_nothing_else(tmp_path):
    """``import tension_zones`` leaves ``XLA_FLAGS`` and the file system alone; a sub-package that
    loads JAX applies the XLA settings, and JAX makes the cache folder at its first compile."""
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items()
           if k not in ("TENSION_ZONES_CACHE", "JAX_COMPILATION_CACHE_DIR", "XDG_CACHE_HOME", "JAX_ENABLE_X64")}
    env.update(HOME=str(home), XLA_FLAGS="--xla_force_host_platform_device_count=1",
               PYTHONPATH=os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]))
    code = """
import os
import tension_zones
print(os.environ["XLA_FLAGS"])
print(os.environ.get("JAX_ENABLE_X64"))
print(sorted(os.listdir(os.path.expanduser("~"))))
import jax
print(jax.config.jax_enable_x64, jax.config.jax_compilation_cache_dir)
"""
    flags, x64, listing, config = _run(code, env)
    assert flags == "--xla_force_host_platform_device_count=1"
    assert x64 == "1" and listing == "[]" and config == "True None"
    assert list(home.iterdir()) == []

    code = """
import os
import jax, jax.numpy as jnp
import tension_zones
import tension_zones.model
print(os.environ["XLA_FLAGS"])
print(jax.config.jax_compilation_cache_dir)
print(os.path.isdir(jax.config.jax_compilation_cache_dir))
jax.jit(lambda x: jnp.sin(x) * 2.0)(jnp.arange(3.0)).block_until_ready()
print(os.path.isdir(jax.config.jax_compilation_cache_dir))
"""
    flags, folder, before, after = _run(code, env)
    assert flags.split() == ["--xla_force_host_platform_device_count=1",
                             "--xla_cpu_enable_concurrency_optimized_scheduler=false"]
    assert folder == str(home / ".cache" / "tension-zones" / "jax")
    assert (before, after) == ("False", "True")
