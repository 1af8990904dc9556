"""The package's persistent compilation cache (tension_zones/_xla.py): where it goes, how it is turned
off, and that a second process compiles from it."""

import os
import subprocess
import sys

from tension_zones._xla import cache_dir

PROBE = (
    "import tension_zones.model, jax, jax.numpy as jnp, time\n"
    "print(jax.config.jax_compilation_cache_dir or os.environ.get('JAX_COMPILATION_CACHE_DIR'))\n"
)


def _probe(env):
    code = "import os\n" + PROBE
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip().splitlines()[-1]


def _env(**changes):
    env = {k: v for k, v in os.environ.items() if k not in ("TENSION_ZONES_CACHE", "JAX_COMPILATION_CACHE_DIR")}
    env.update(changes)
    return env


def test_cache_folder_from_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("TENSION_ZONES_CACHE", str(tmp_path / "c"))
    assert cache_dir() == str(tmp_path / "c") and (tmp_path / "c").is_dir()
    for off in ("0", "off", "false"):
        monkeypatch.setenv("TENSION_ZONES_CACHE", off)
        assert cache_dir() is None
    monkeypatch.delenv("TENSION_ZONES_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == str(tmp_path / "xdg" / "tension-zones" / "jax")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setenv("TENSION_ZONES_CACHE", str(blocker / "sub"))  # cannot be created: no cache
    assert cache_dir() is None
    assert cache_dir(create=False) is None


def test_the_folder_is_only_checked_without_create(tmp_path, monkeypatch):
    monkeypatch.setenv("TENSION_ZONES_CACHE", str(tmp_path / "a" / "b"))
    assert cache_dir(create=False) == str(tmp_path / "a" / "b") and not (tmp_path / "a").exists()


def test_a_fresh_process_uses_the_cache_and_a_users_jax_setting_wins(tmp_path):
    assert _probe(_env(TENSION_ZONES_CACHE=str(tmp_path / "c"))) == str(tmp_path / "c")
    assert _probe(_env(TENSION_ZONES_CACHE="0")) == "None"
    mine = str(tmp_path / "mine")
    assert _probe(_env(TENSION_ZONES_CACHE=str(tmp_path / "c"), JAX_COMPILATION_CACHE_DIR=mine)) == mine


def test_fast_compile_options_only_where_jaxlib_has_them_and_change_no_result(monkeypatch):
    from tension_zones import _xla

    level = {"xla_backend_optimization_level": 3}
    for version, expected in (
        ((0, 4, 30), {}),
        ((0, 5, 1), {}),
        ((0, 5, 3), {"xla_cpu_use_fusion_emitters": False}),
        ((0, 10, 2), {"xla_cpu_use_fusion_emitters": False}),
    ):
        monkeypatch.setattr(_xla, "_jaxlib_version", lambda v=version: v)
        assert _xla.fast_compile_options() == {**level, **expected}, version
        assert _xla.fast_compile_options(optimise=False) == {**level, **expected, **{k: 0 for k in level}}
        assert _xla.fast_compile_flag() == "".join(f"--{k}=false" for k in expected), version
    monkeypatch.undo()
    assert len(_xla._jaxlib_version()) >= 2  # the installed jaxlib's version is read

    # against the default codegen: in a child without the suite's process-wide flag (conftest.py)
    code = """
import jax, jax.numpy as jnp, numpy as np
import tension_zones
from tension_zones import _xla

def f(x):  # fusions of elementwise work, a reduction and a scatter, as in the calibration's programs
    y = jnp.sin(x) * jnp.exp(-x**2) + jnp.sqrt(1.0 + x**2)
    return y.at[::3].add(jnp.cumsum(y)[::3]).sum() + jnp.tanh(y) @ y

x = jnp.linspace(-2.0, 3.0, 301)
fast = jax.jit(f, compiler_options=_xla.fast_compile_options())  # the installed jaxlib accepts them
np.testing.assert_allclose(fast(x), jax.jit(f)(x), rtol=1e-12)
fast_grad = jax.jit(jax.grad(f), compiler_options=_xla.fast_compile_options())  # (top-level jits only)
np.testing.assert_allclose(fast_grad(x), jax.jit(jax.grad(f))(x), rtol=1e-12, atol=1e-14)
print("equal")
"""
    flags = " ".join(f for f in os.environ.get("XLA_FLAGS", "").split() if "fusion_emitters" not in f)
    out = subprocess.run(
        [sys.executable, "-c", code], env=dict(os.environ, XLA_FLAGS=flags), capture_output=True, text=True, check=False
    )
    assert out.returncode == 0 and out.stdout.strip() == "equal", out.stderr[-2000:]
    if _xla.fast_compile_flag():  # the suite runs with the same switch for the whole process
        assert _xla.fast_compile_flag() in os.environ["XLA_FLAGS"]


def test_programs_kept_on_disk_are_loaded_without_tracing_and_keyed_by_sources(tmp_path, monkeypatch):
    import jax
    import jax.numpy as jnp
    import numpy as np

    from tension_zones import _xla

    monkeypatch.setenv("TENSION_ZONES_CACHE", str(tmp_path / "c"))
    traced = []

    def f(x, d):
        traced.append(1)  # runs only while tracing
        return {
            "y": jnp.sin(x) @ d["a"],
            "z": jax.lax.while_loop(lambda c: c[0] < 5, lambda c: (c[0] + 1, c[1] * 2.0), (0, x))[1],
        }

    args = (jnp.linspace(0.0, 1.0, 7), {"a": jnp.ones((7, 2))})
    want = jax.jit(f)(*args)
    first = _xla.stored_program(jax.jit(f), args, "test f")
    folder = tmp_path / "c" / "programs"
    assert len(list(folder.iterdir())) == 1
    traced.clear()
    again = _xla.stored_program(jax.jit(f), args, "test f")  # as a later process: loaded, not traced
    for got in (first(*args), again(*args)):
        np.testing.assert_array_equal(got["y"], want["y"])
        np.testing.assert_array_equal(got["z"], want["z"])
    assert traced == []
    # other shapes, another key or other package sources: another program
    _xla.stored_program(jax.jit(f), (jnp.zeros(3), {"a": jnp.ones((3, 2))}), "test f")
    _xla.stored_program(jax.jit(f), args, "test g")
    monkeypatch.setattr(_xla, "_sources_digest", lambda: "edited")
    _xla.stored_program(jax.jit(f), args, "test f")
    assert len(list(folder.iterdir())) == 4
    # a damaged file is exported again, the result still right
    for p in folder.iterdir():
        p.write_bytes(b"not a program")
    np.testing.assert_array_equal(_xla.stored_program(jax.jit(f), args, "test f")(*args)["y"], want["y"])
    # no cache folder: the function itself
    monkeypatch.setenv("TENSION_ZONES_CACHE", "0")
    g = jax.jit(f)
    assert _xla.stored_program(g, args, "test f") is g


def test_classes_outside_the_package_are_keyed_by_their_source(tmp_path, monkeypatch):
    import importlib

    from tension_zones import _xla
    from tension_zones.calibration.effects import Backlash, Effect

    assert _xla.classes_digest([Backlash, Effect]) == ""  # the package's own: its sources' digest covers them
    mod = tmp_path / "my_effect.py"
    mod.write_text("from tension_zones.calibration.effects import Effect\nclass Mine(Effect):\n    name = 'mine'\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    Mine = importlib.import_module("my_effect").Mine
    d1 = _xla.classes_digest([Backlash, Mine])
    mod.write_text(mod.read_text() + "# edited\n")
    assert len(d1) == 64 and _xla.classes_digest([Mine]) != d1
    Local = type("Local", (Effect,), {"__module__": "__main__"})  # e.g. defined in a notebook
    assert _xla.classes_digest([Local]) is None


def test_clearing_jax_caches_frees_the_memory_maps_the_suite_watches():
    """The suite's guard against ``vm.max_map_count`` (``conftest._free_compiled_programs``) relies on
    ``jax.clear_caches`` unloading compiled programs: each loaded one holds memory maps until then."""
    import gc

    import jax
    import jax.numpy as jnp
    import pytest
    from conftest import _memory_maps

    if _memory_maps() == 0:
        pytest.skip("no /proc/self/maps on this system")
    jax.clear_caches()
    gc.collect()
    before = _memory_maps()
    fns = [jax.jit(lambda x, k=k: jnp.sin(x) * k) for k in range(40)]
    for k, f in enumerate(fns):
        f(jnp.ones(3 + k)).block_until_ready()
    loaded = _memory_maps()
    jax.clear_caches()
    gc.collect()
    assert loaded - before >= 40  # at least one map per program
    assert _memory_maps() - before < 0.5 * (loaded - before)  # most freed, though the functions live on
