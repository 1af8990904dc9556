"""Design-space exploration: per-design statistics, chunks, recompiles, resuming, two
jax.distributed processes, the Pareto front and the space file's errors.

Compiled programs are shared between tests: the explorations here use 3 or 4 wires, 4 designs per
chunk and the default poses per step, unless a test is about the chunk sizes.
"""

import json
import os
import socket
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tension_zones as tz
from tension_zones.analysis import _sweep
from tension_zones.analysis._sweep import compiled_chunk_count, grid_deg, sweep_configs, sweep_designs, sweep_grid
from tension_zones.cli import main
from tension_zones.design import _explore
from tension_zones.design._explore import _kinematic_pose, _stats, explore_designs
from tension_zones.design._optimise import chain_spread
from tension_zones.model._statics import as_wrench

rad = np.radians
TH, DE = rad(grid_deg(85, 17)), rad(grid_deg(360, 30))  # 6 x 13 poses: quick
SMALL = {"theta_L_deg": [0, 85, 17], "delta_deg": [0, 360, 30], "chunks": {"designs": 4}}
NUMPY = {"max": np.max, "min": np.min, "mean": np.mean, "nanmax": np.nanmax, "nanmean": np.nanmean}


def batch(designs):
    return jax.tree_util.tree_map(lambda *x: np.stack(x), *designs)


def reference(design, th, de, dq, load=None):
    """The statistics the slow way: the single-design sweeps, reduced with NumPy."""
    res = sweep_grid(tz.pose_metrics, design, th, de, dq, quiet=True)
    res["controllable"] = res["n_taut"] >= 2
    if load is not None:
        res.update(sweep_grid(tz.compliance_pose, design, th, de, tz.model.as_wrench(load), quiet=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN: NaN, as ours
        return {name: NUMPY[op](res[key].astype(float)) for name, key, op in _stats(load is not None)}


def assert_stats_equal(got, refs, rtol=1e-12):
    for i, ref in enumerate(refs):
        for k, v in ref.items():
            np.testing.assert_allclose(got[k][i], v, rtol=rtol, atol=1e-300, err_msg=f"design {i}, {k}")


designs_st = st.lists(  # length, pitch radius, offsets of the three wires from even spacing (rad); the
    # lengths from 8 mm: a pitch radius above half the length is refused (Design: MAX_RADIUS_PER_LENGTH)
    st.tuples(st.floats(8.0, 40.0), st.floats(0.5, 4.0), *[st.floats(-0.9, 0.9)] * 3),
    min_size=1,
    max_size=6,
)


@settings(max_examples=10, deadline=None)
@given(values=designs_st, dq=st.floats(0.05, 1.0))
def test_statistics_equal_the_single_design_sweep(values, dq):
    """Acceptance: per-design statistics equal the single-design sweep's to 1e-12 (float64), for
    random designs (up to 6: two chunks of 4, the last padded)."""
    designs = [
        tz.Design(3, L, r, wire_angles=rad([0.0, 120.0, 240.0]) + np.array(offsets)) for L, r, *offsets in values
    ]
    got = explore_designs(batch(designs), TH, DE, dq, designs_per_chunk=4, quiet=True)
    assert_stats_equal(got, [reference(d, TH, DE, dq) for d in designs])


def test_statistics_with_a_load_and_the_papers_grid(rng):
    """The compliance statistics (NaN where the wires cannot hold a pose), on the paper's grid (2610
    poses: two steps of 1320, the last padded)."""
    th, de = rad(grid_deg(85, 5)), rad(grid_deg(360, 2.5))
    # the first design's wires lie on a half circle: some poses cannot be held by pulling
    designs = [
        tz.Design(
            3,
            rng.uniform(10, 30),
            rng.uniform(0.8, 3),
            wire_stiffness=rng.uniform(55, 105),
            backbone_EI=rng.uniform(100, 2000),
            preload=p,
            wire_angles=rad(angles),
        )
        for p, angles in ((0.0, [0.0, 90.0, 180.0]), (0.0, [10.0, 125.0, 250.0]), (3.0, [0.0, 120, 240]))
    ]
    load = [5.0, -2.0, 1.0]
    got = explore_designs(batch(designs), th, de, 0.4, load, designs_per_chunk=4, quiet=True)
    refs = [reference(d, th, de, 0.4, load) for d in designs]
    assert_stats_equal(got, refs)
    assert 0 < got["statics_feasible_fraction"][0] < 1  # some poses need pushing: NaN skipped there


def test_no_recompile_when_only_values_change(rng):
    """New design values, number of designs, dq, load and grid (values and size): the same program."""

    def some(n_designs, n=3):
        return batch(
            [
                tz.Design(
                    n,
                    rng.uniform(10, 30),
                    rng.uniform(1, 3),
                    wire_stiffness=rng.uniform(50, 100),
                    preload=rng.uniform(0, 2),
                )
                for _ in range(n_designs)
            ]
        )

    explore_designs(some(5), TH, DE, 0.4, designs_per_chunk=4, quiet=True)
    explore_designs(some(2), TH, DE, 0.4, [5.0, 0, 0], designs_per_chunk=4, quiet=True)
    n0 = compiled_chunk_count()
    explore_designs(some(9), TH + 0.01, DE, 0.7, designs_per_chunk=4, quiet=True)
    explore_designs(some(3), rad(grid_deg(80, 4)), rad(grid_deg(350, 50)), 0.2, designs_per_chunk=4, quiet=True)
    explore_designs(some(6), TH, DE, 0.4, [1.0, 2.0, -3.0, 0.5, 0, 0], designs_per_chunk=4, quiet=True)
    assert compiled_chunk_count() == n0


def test_engine_errors_are_clear(d3):
    one = batch([d3, d3])
    with pytest.raises(TypeError, match="leading axis"):
        sweep_designs(_kinematic_pose, d3, TH, DE, 0.4, stats=[("a", "dp_max_full", "max")])
    with pytest.raises(ValueError, match="no output 'nope'"):
        sweep_designs(_kinematic_pose, one, TH, DE, 0.4, stats=[("a", "nope", "max")])
    with pytest.raises(ValueError, match="unknown reduction 'median'"):
        sweep_designs(_kinematic_pose, one, TH, DE, 0.4, stats=[("a", "dp_max_full", "median")])
    with pytest.raises(ValueError, match="designs_per_chunk must be a positive integer"):
        sweep_designs(_kinematic_pose, one, TH, DE, 0.4, stats=[("a", "dp_max_full", "max")], designs_per_chunk=0)


# ------------------------------------------------------------------------------------------------
# Several segments: robots over configuration samples
# ------------------------------------------------------------------------------------------------
ROBOTS = {
    "segments": [
        {"length_mm": 40.0, "n_wires": 4, "pitch_radius_mm": [2.0, 4.0]},
        {"length_mm": 30.0, "n_wires": [3, 4], "pitch_radius_mm": [1.0, 3.0], "preload_N": {"values": [0.0, 1.0]}},
    ],
    "max_bend_deg": 60.0,
    "samples": 50,
    "sample": {"method": "halton", "designs": 5},
    "chunks": {"designs": 4},
}


def _config_with_statics(robot, B, dq, wrench):
    return {**tz.config_metrics(robot, B, dq), **tz.config_compliance(robot, B, wrench)}


def test_a_robot_s_statistics_equal_its_own_sweep(monkeypatch):
    """Per-robot statistics equal the single robot's configuration sweep reduced with NumPy (to 1e-12),
    for the robots of a space (two chunks of 4, the last padded), under a load: every kinematic column
    and the compliance's (``config_compliance``; the kinematic program alone runs in the CLI test of
    the shipped space below); each robot is the layout the row says. The chunk's memory estimate
    (``_explore.chunk_memory``, what the resource check goes by) is above XLA's analysis of its program."""
    load = [0.5, 0.2, -0.3]
    space = tz.parse_space({**ROBOTS, "load_N": load})
    batch, cols = space.batch((4, 3)), space.columns((4, 3))
    calls = []
    chunk_jit = _sweep._designs_chunk_jit
    monkeypatch.setattr(_sweep, "_designs_chunk_jit", lambda *a: calls.append(a) or chunk_jit(*a))
    got = explore_designs(batch, space.configs, None, 0.4, load, designs_per_chunk=4, quiet=True)
    mem = chunk_jit.lower(*calls[0]).compile().memory_analysis()
    used = mem.temp_size_in_bytes + mem.argument_size_in_bytes + mem.output_size_in_bytes
    assert calls[0][2][0] == space.poses_per_chunk and 0 < used < _explore.chunk_memory(space, (4, 3))
    for i in range(space.count((4, 3))):
        robot = jax.tree_util.tree_map(lambda x: x[i], batch)  # noqa: B023  (used at once)
        assert float(robot.segments[1].pitch_radius) == cols["pitch_radius_mm_2"][i]
        np.testing.assert_allclose(np.asarray(robot.route_radii)[4:, 0], cols["pitch_radius_mm_1"][i])
        np.testing.assert_allclose(np.degrees(np.asarray(robot.segments[1].wire_angles)), [15.0, 135.0, 255.0])
        res = sweep_configs(_config_with_statics, robot, space.configs, 0.4, as_wrench(load), quiet=True)
        spread = jax.vmap(lambda B: chain_spread(robot, B))(space.configs)  # noqa: B023
        res["controllable"] = np.asarray(spread) > _explore.SPAN_TOL
        for name, key, op in _stats(True):
            np.testing.assert_allclose(got[name][i], NUMPY[op](res[key].astype(float)), rtol=1e-12, err_msg=name)
    assert 0 < got["controllable_fraction"].min() < 1  # three wires in a segment: one-wire sectors


def test_no_recompile_when_only_a_robot_s_values_change():
    """New numbers, number of robots and of configurations, bending and dq: the same program."""
    space = tz.parse_space(ROBOTS)
    explore_designs(space.batch((4, 4)), space.configs, None, 0.4, designs_per_chunk=4, quiet=True)
    n0 = compiled_chunk_count()
    segments = [
        {"length_mm": 30.0, "n_wires": 4, "pitch_radius_mm": 2.5, "preload_N": 1.0},
        {"length_mm": 20.0, "n_wires": 4, "pitch_radius_mm": [1.0, 2.0], "backbone_EI_Nmm2": [100.0, 2000.0]},
    ]
    other = tz.parse_space({**ROBOTS, "segments": segments, "samples": 90, "max_bend_deg": 80.0})
    explore_designs(other.batch((4, 4)), other.configs, None, 0.7, designs_per_chunk=4, quiet=True)
    assert compiled_chunk_count() == n0


def test_a_one_segment_space_in_the_segments_form_is_the_one_segment_space():
    from tension_zones.design._space import DEFAULTS, ROBOT_KEYS, SEGMENT_KEYS

    flat = {**SMALL, "n_wires": [3, 4], "length_mm": [10.0, 20.0], "pitch_radius_mm": 2.0, "preload_N": 0.5}
    form = {k: v for k, v in flat.items() if k not in SEGMENT_KEYS}
    form["segments"] = [{k: flat[k] for k in SEGMENT_KEYS if k in flat}]
    a, b = tz.parse_space(flat), tz.parse_space(form)
    assert_tables_identical(tz.explore(a, quiet=True), tz.explore(b, quiet=True))
    assert set(a.raw) == set(DEFAULTS) - set(ROBOT_KEYS)  # a one-segment exploration's identity as it was


# ------------------------------------------------------------------------------------------------
# Spaces and the Pareto front
# ------------------------------------------------------------------------------------------------
def test_halton_is_scipys_unscrambled_sequence():
    from scipy.stats import qmc

    np.testing.assert_allclose(
        tz.design.halton(200, 6), qmc.Halton(6, scramble=False).random(201)[1:], rtol=0, atol=1e-15
    )


def test_space_samples():
    grid = tz.parse_space(
        {
            "n_wires": [3, 4],
            "pitch_radius_mm": [1, 3],
            "length_mm": {"values": [10, 20]},
            "wire_angle_offset_deg": [-5, 5],
            "sample": {"points": 3},
        }
    )
    assert grid.count(3) == 3 * 2 * 3**3 and grid.count(4) == 3 * 2 * 3**4
    cols = grid.columns(3)
    assert set(cols["pitch_radius_mm"]) == {1.0, 2.0, 3.0} and set(cols["length_mm"]) == {10.0, 20.0}
    assert np.all(np.isnan(cols["wire_angle_4_deg"]))
    assert np.all(np.abs(cols["wire_angle_2_deg"] - 120) <= 5)
    d = grid.batch(4)
    assert d.n_wires == 4 and d.wire_angles.shape == (grid.count(4), 4)
    halton = tz.parse_space(
        {"n_wires": [3, 5], "pitch_radius_mm": [1, 3], "sample": {"method": "halton", "designs": 50}}
    )
    a, b = halton.columns(3), halton.columns(5)
    np.testing.assert_array_equal(a["pitch_radius_mm"], b["pitch_radius_mm"])  # paired across counts
    assert a["pitch_radius_mm"].min() >= 1 and a["pitch_radius_mm"].max() <= 3


def brute_front(X):
    return np.array([not np.any(np.all(X <= x, axis=1) & np.any(X < x, axis=1)) for x in X])


@pytest.mark.parametrize("k", [2, 3])
def test_pareto_front_matches_brute_force(rng, k):
    X = rng.integers(0, 12, size=(400, k)).astype(float)  # many ties
    X[5, 0] = np.nan
    table = {f"c{j}": X[:, j] for j in range(k)}
    on = tz.pareto_front(table, list(table))
    ok = np.isfinite(X).all(axis=1)
    np.testing.assert_array_equal(on[ok], brute_front(X[ok]))
    assert not on[5]
    on_max = tz.pareto_front(table, ["max:c0"] + [f"c{j}" for j in range(1, k)])
    Y = X.copy()
    Y[:, 0] *= -1
    np.testing.assert_array_equal(on_max[ok], brute_front(Y[ok]))
    with pytest.raises(ValueError, match="not a column"):
        tz.pareto_front(table, ["c0", "nope"])


# ------------------------------------------------------------------------------------------------
# Output folder: table, resuming
# ------------------------------------------------------------------------------------------------
SPACE = {
    **SMALL,
    "n_wires": 3,
    "pitch_radius_mm": [1.0, 3.0],
    "wire_angle_offset_deg": [-20, 20],
    "sample": {"method": "halton", "designs": 18},
}


def assert_tables_identical(a, b):
    assert list(a) == list(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_interrupted_exploration_resumes_without_recomputing(tmp_path, monkeypatch):
    space = tz.parse_space(SPACE)  # 18 designs in chunks of 4: 5 chunks
    whole = tz.explore(space, tmp_path / "whole", quiet=True)

    calls = {"chunks": 0, "saves": 0}
    real_chunk, real_save = _sweep._designs_chunk_jit, _explore._Store.save

    def counting_chunk(*a, **k):
        calls["chunks"] += 1
        return real_chunk(*a, **k)

    def failing_save(self, *a):
        if calls["saves"] == 3:
            raise RuntimeError("interrupted")  # as if interrupted after three chunks were saved
        calls["saves"] += 1
        return real_save(self, *a)

    monkeypatch.setattr(_sweep, "_designs_chunk_jit", counting_chunk)
    monkeypatch.setattr(_explore._Store, "save", failing_save)
    with pytest.raises(RuntimeError, match="interrupted"):
        tz.explore(space, tmp_path / "run", quiet=True)
    manifest = json.loads((tmp_path / "run" / "manifest.json").read_text())
    assert manifest["done"] == {"3": [0, 1, 2]} and not manifest["complete"]

    monkeypatch.setattr(_explore._Store, "save", real_save)
    calls["chunks"] = 0
    lines = []
    resumed = tz.explore(space, tmp_path / "run", quiet=True, log=lines.append)
    assert lines == [f"resuming the exploration in {str(tmp_path / 'run')!r}: 3 of 5 chunks done"]
    assert calls["chunks"] == 2  # the three saved chunks are not computed again
    assert_tables_identical(resumed, whole)
    assert (tmp_path / "run" / "table.csv").read_text() == (tmp_path / "whole" / "table.csv").read_text()
    assert json.loads((tmp_path / "run" / "manifest.json").read_text())["complete"]
    assert not list((tmp_path / "run").rglob(".*"))  # every file renamed into place, the lock released


DISTRIBUTED = textwrap.dedent("""
    import json, sys
    import jax
    jax.distributed.initialize(coordinator_address="localhost:" + sys.argv[1], num_processes=2,
                               process_id=int(sys.argv[2]))
    import tension_zones as tz
    from tension_zones.analysis import _sweep
    calls, chunk = [], _sweep._designs_chunk_jit
    _sweep._designs_chunk_jit = lambda *a: calls.append(1) or chunk(*a)
    table = tz.explore(tz.parse_space(json.loads(sys.argv[4])), sys.argv[3], quiet=True)
    print("process", jax.process_index(), "of", jax.process_count(), "table", table is not None,
          "chunks", len(calls), "devices", len(jax.local_devices()))
""")


ONE_PROCESS = textwrap.dedent("""
    import json, sys
    import tension_zones as tz
    tz.explore(tz.parse_space(json.loads(sys.argv[2])), sys.argv[1], quiet=True)
""")


def free_port():
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def test_two_jax_distributed_processes_give_the_same_table(tmp_path, default_codegen_env):
    """Acceptance: two processes on localhost (CPU) give the one-process table, bit for bit. Each has
    two local devices, over which each chunk's designs are split; the one process has one device (a
    child too, with the same codegen)."""
    path = os.pathsep.join([str(Path(__file__).parents[1])] + sys.path)
    env = default_codegen_env("--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu", PYTHONPATH=path)
    port, out = str(free_port()), tmp_path / "two"
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", DISTRIBUTED, port, str(i), str(out), json.dumps(SPACE)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for i in (0, 1)
    ]
    procs.append(
        subprocess.Popen(
            [sys.executable, "-c", ONE_PROCESS, str(tmp_path / "one"), json.dumps(SPACE)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=default_codegen_env(JAX_PLATFORMS="cpu", PYTHONPATH=path),
        )
    )
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (o, e) in zip(procs, outs):
        assert p.returncode == 0, e[-3000:]
    one = dict(np.load(tmp_path / "one" / "table.npz"))
    # 5 chunks: process 0 takes 0, 2, 4 and process 1 takes 1, 3; process 0 writes the table
    assert "process 0 of 2 table True chunks 3 devices 2" in outs[0][0]
    assert "process 1 of 2 table False chunks 2 devices 2" in outs[1][0]
    assert_tables_identical(dict(np.load(out / "table.npz")), one)


# ------------------------------------------------------------------------------------------------
# Command line
# ------------------------------------------------------------------------------------------------
def write_space(tmp_path, space, name="space.json"):
    path = tmp_path / name
    path.write_text(json.dumps(space) if not isinstance(space, str) else space)
    return str(path)


def test_cli_explore_writes_table_front_and_plots_and_resumes(tmp_path, capsys):
    space = write_space(tmp_path, {**SPACE, "load_N": [5.0, 0.0, 0.0]})
    out = tmp_path / "out"
    assert main(["explore", "--space", space, "--out", str(out)]) == 0
    text = capsys.readouterr()
    assert "explored 18 designs (3 wires)" in text.out and "Pareto front of pitch_radius_mm" in text.out
    assert "3 wires" in text.err  # the progress bar
    for name in ("table.npz", "table.csv", "front.csv", "front.png", "parallel.png", "manifest.json"):
        assert (out / name).stat().st_size > 0, name
    table = dict(np.load(out / "table.npz"))
    assert table["deflection_mm_reduced_worst"].shape == (18,)
    header = (out / "table.csv").read_text().splitlines()[0].split(",")
    assert header == list(table)
    # the same exploration again: resumed (nothing to compute), said in one line; --quiet: no bar
    assert (
        main(
            [
                "explore",
                "--space",
                space,
                "--out",
                str(out),
                "--quiet",
                "--front",
                "max:wire_stiffness_N_per_mm,deflection_mm_reduced_worst",
            ]
        )
        == 0
    )
    text = capsys.readouterr()
    assert "resuming the exploration" in text.out and "5 of 5 chunks done" in text.out
    assert text.err == ""


def test_cli_explores_the_shipped_two_segment_space_and_resumes(tmp_path, capsys):
    space, out = str(tz.example_path("design/two_segments.space.json")), tmp_path / "out"
    assert main(["explore", "--space", space, "--out", str(out)]) == 0
    text = capsys.readouterr()
    assert "exploring 32 designs x 128 configurations" in text.out and "4+4 wires" in text.err
    assert "explored 32 designs (4+3, 4+4 wires)" in text.out and "Pareto front of pitch_radius_mm_max" in text.out
    table = dict(np.load(out / "table.npz"))
    assert table["n_wires_2"].tolist() == [3] * 16 + [4] * 16 and set(table["n_wires"].tolist()) == {7, 8}
    np.testing.assert_array_equal(table["pitch_radius_mm_1"][:16], table["pitch_radius_mm_1"][16:])  # paired
    assert np.all(table["controllable_fraction"][16:] == 1) and np.all(table["controllable_fraction"][:16] < 1)
    front = (out / "front.csv").read_text().splitlines()
    assert len(front) > 1 and all(row.split(",")[list(table).index("n_wires")] == "8" for row in front[1:])
    for name in ("table.csv", "front.png", "parallel.png", "manifest.json"):
        assert (out / name).stat().st_size > 0, name
    chunks = sorted(p.name for p in (out / "chunks").iterdir())
    assert chunks == ["n4+3_000000.npy", "n4+3_000001.npy", "n4+4_000000.npy", "n4+4_000001.npy"]
    assert main(["explore", "--space", space, "--out", str(out), "--quiet"]) == 0
    assert "resuming the exploration" in capsys.readouterr().out


@pytest.mark.parametrize(
    "space, needle",
    [
        ({"pitch_radius": [1, 2]}, "unknown space key(s) ['pitch_radius']"),
        ({"pitch_radius_mm": [3.0, 1.0]}, "space key 'pitch_radius_mm': min 3.0 is larger than max 1.0"),
        ({"length_mm": [20, 20]}, "space key 'length_mm': [20.0, 20.0] is an empty range"),
        ({"wire_stiffness_N_per_mm": {"values": []}}, "space key 'wire_stiffness_N_per_mm': values must be"),
        ({"n_wires": [2, 3]}, "space key 'n_wires': must be a list of integers from 3 to 16"),
        ({"n_wires": 2}, "space key 'n_wires'"),
        ({"pitch_radius_mm": [-1, 2]}, "space key 'pitch_radius_mm': must be > 0.0"),
        ({"theta_L_deg": [80, 10, 5]}, "space key 'theta_L_deg': min 80.0 is larger than max 10.0"),
        ({"sample": {"method": "sobol"}}, "space key 'sample.method'"),
        ({"sample": {"designs": 100}}, "space key 'sample.designs': does not go with method 'grid'"),
        ({"sample": {"method": "halton", "desings": 100}}, "space key 'sample': unknown sub-key(s) ['desings']"),
        ({"wire_angle_offset_deg": [-50, 50]}, "space key 'wire_angle_offset_deg': spans 100 deg"),
        ({"chunks": {"designs": 0}}, "space key 'chunks.designs': must be a positive integer"),
        ({"load_N": [1, 2]}, "space key 'load_N'"),
        ("[1, 2]", "a design space must be a JSON object"),
        ("{", "is not valid JSON"),
    ],
)
def test_bad_space_files_are_one_line_errors(tmp_path, capsys, space, needle):
    out = tmp_path / "out"
    assert main(["explore", "--space", write_space(tmp_path, space), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and err.startswith("tension-zones: error:")
    assert not out.exists()


def test_cli_out_folder_is_checked_before_computing(tmp_path, capsys):
    space = write_space(tmp_path, SPACE)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "notes.txt").write_text("mine")
    (tmp_path / "file").write_text("")
    other = write_space(tmp_path, {**SPACE, "pitch_radius_mm": [1.0, 2.0]}, "other.json")
    n0 = compiled_chunk_count()
    cases = [
        ([space, tmp_path / "full"], "is not empty and holds no exploration; refusing to overwrite it"),
        ([space, tmp_path / "file" / "out"], "cannot write the output folder"),
        ([space, tmp_path / "new", "--front", "pitch_radius_mm,nope"], "front column 'nope' is not"),
        ([space, tmp_path / "new", "--front", "pitch_radius_mm"], "two or three columns"),
        ([space, tmp_path / "new", "--coordinator", "localhost:1"], "--num-processes is missing"),
    ]
    for (sp, out, *extra), needle in cases:
        assert main(["explore", "--space", sp, "--out", str(out), *extra]) == 2
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1, err
    assert (tmp_path / "full" / "notes.txt").read_text() == "mine" and not (tmp_path / "new").exists()
    assert compiled_chunk_count() == n0  # refused before any computation
    # a folder holding another exploration: refused, naming what differs
    (tmp_path / "done").mkdir()
    manifest = {
        "format": _explore.FORMAT,
        "space": tz.parse_space(json.loads(Path(space).read_text())).raw,
        "columns": [s[0] for s in _stats(False)],
        "done": {"3": []},
        "chunks_total": 5,
    }
    (tmp_path / "done" / "manifest.json").write_text(json.dumps(manifest))
    assert main(["explore", "--space", other, "--out", str(tmp_path / "done")]) == 2
    assert "holds another exploration (space key 'pitch_radius_mm' differs)" in capsys.readouterr().err


def test_readme_documents_every_space_key_and_default():
    from tension_zones.design._space import DEFAULTS

    readme = (Path(tz.__file__).parent / "design" / "README.md").read_text()
    for key, value in DEFAULTS.items():
        assert f"| `{key}` | `{json.dumps(value)}` |" in readme, key
