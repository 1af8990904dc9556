import gc
import os
import tempfile

os.environ.setdefault("MPLBACKEND", "Agg")
# one compilation cache for the session, fresh each run (never a stale one from an earlier run) and
# shared by the xdist workers, the notebooks' kernels and the CLI's subprocesses, which inherit it:
# the same calibration programs are compiled once per session, not once per process
if "TENSION_ZONES_CACHE" not in os.environ:
    import atexit
    import shutil

    os.environ["TENSION_ZONES_CACHE"] = tempfile.mkdtemp(prefix="tz-test-jax-cache-")
    atexit.register(shutil.rmtree, os.environ["TENSION_ZONES_CACHE"], True)  # by the process that made it

# the calibrations run on the test's process alone (calibration/_fits.py): the suite already keeps both
# cores busy, and a worker compiles its own programs; one test runs a worker on purpose
os.environ.setdefault("TENSION_ZONES_WORKERS", "0")

# the tests are compile-bound (small inputs, thousands of programs): XLA:CPU's older emitters compile
# them faster (the package's large programs use them already: tension_zones/_xla.py); subprocesses
# inherit the flag. The package's own default codegen is what
# test_xla_cache.py compares against, in a child process without it.
from tension_zones._xla import fast_compile_flag  # (no JAX import)

# For the same reason LLVM optimises the suite's programs at level 0 (XLA's default: 3), except the
# package's long-running ones, which pin level 3 (``fast_compile_options``). Results are the same (no
# fast math either way).
_LEVEL_0 = "--xla_backend_optimization_level=0"
for _flag in (fast_compile_flag(), _LEVEL_0):
    if _flag and _flag.split("=")[0] not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_flag}".strip()

import jax
import numpy as np
import pytest
from hypothesis import settings

import tension_zones as tz

settings.register_profile("ci", max_examples=40, deadline=None)
settings.load_profile("ci")


def _maps_soft_limit() -> int:
    """70 % of the kernel's limit (45 871 of the default 65 530): the rest, about 700 programs, is
    left for one test (a few thousand maps, the most one test adds)."""
    try:
        with open("/proc/sys/vm/max_map_count") as f:
            return int(0.7 * int(f.read()))
    except (OSError, ValueError):
        return 45_000


_MAPS_SOFT_LIMIT = _maps_soft_limit()


def _memory_maps() -> int:
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:  # not Linux: no such limit to watch
        return 0


@pytest.fixture(autouse=True)
def _free_compiled_programs():
    """Drop JAX's in-memory compiled programs when this worker holds too many. Each program XLA:CPU
    loads holds about 28 memory maps (its code and data pages), and a worker of the suite compiles
    thousands: one reached 53 297 maps of Linux's default limit of 65 530 (``vm.max_map_count``) in a
    full run, and past that limit loading the next program crashes the worker (seen three times, inside
    ``deserialize_executable``, always late in the run). Clearing after every module instead cost the
    suite its speed (programs shared between modules compiled again), so only past a soft limit, and a
    high one: each clear costs the programs compiled again after it."""
    yield
    if _memory_maps() > _MAPS_SOFT_LIMIT:
        jax.clear_caches()
        gc.collect()


@pytest.fixture
def d3():
    return tz.Design(3, 20.0, 2.0)


@pytest.fixture
def d4():
    return tz.Design(4, 20.0, 2.0)


@pytest.fixture
def default_codegen_env():
    """``os.environ`` for a child process that compiles at LLVM's default level (the suite's level 0
    left out), with a function ``(**changes) -> env`` adding ``XLA_FLAGS`` entries and variables: for
    the tests of bit-for-bit equal results over other device layouts, which the package's codegen gives
    and level 0 does not (there a few sweep values differ in the last bit between batch shapes)."""
    flags = " ".join(f for f in os.environ.get("XLA_FLAGS", "").split() if f != _LEVEL_0)

    def env(extra_flags="", **changes):
        return dict(os.environ, XLA_FLAGS=f"{flags} {extra_flags}".strip(), **changes)

    return env


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def two_segments(preload: float = 0.0) -> tz.Robot:
    """A two-segment robot: 3 wires evenly spaced, then 4 at uneven angles, ``preload`` (N) on each."""
    proximal = tz.Design(3, 40.0, 3.0, backbone_EI=2000.0, wire_stiffness=40.0, preload=preload)
    angles = np.radians([10, 100, 190, 280])
    distal = tz.Design(4, 50.0, 2.5, angles, backbone_EI=1500.0, wire_stiffness=60.0, preload=preload)
    return tz.Robot([proximal, distal])


#: A small optimiser scenario (3 wires, 2 starts x 40 steps, a coarse task grid): tests that run the
#: optimiser for something else than its result take it, so that they share its one compiled program.
SMALL_SCENARIO = {
    "n_wires": [3],
    "pitch_radius_mm": [1.0, 2.5],
    "wire_stiffness_N_per_mm": [55.0, 105.0],
    "theta_L_deg": [30.0, 80.0, 25.0],
    "delta_deg": [0.0, 350.0, 25.0],
    "optimizer": {"starts": 2, "steps": 40, "learning_rate": 0.1},
}


def omega_jacobian(fn_R, x):
    """Columns vee(dR/dx_i R^T) for a rotation-valued fn of a vector x."""
    R = fn_R(x)
    dR = jax.jacfwd(fn_R)(x)
    W = np.einsum("ijk,lj->kil", np.asarray(dR), np.asarray(R))
    return np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=0)


def pytest_collection_modifyitems(config, items):
    """The end-to-end cases (``slow``) first: under ``-n 2`` the workers then end on short tests
    together, instead of one waiting for the other's notebook (the same order on every worker)."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
