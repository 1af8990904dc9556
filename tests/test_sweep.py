"""The sweep engine (chunking, padding, recompiles, sharding, progress) and `tension-zones sweep`."""

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_metrics import ref_measures

import tension_zones as tz
from tension_zones.analysis._metrics import MEASURES
from tension_zones.analysis._sweep import compiled_chunk_count, grid_deg, sweep_grid, sweep_poses
from tension_zones.cli import main

rad = np.radians


def tip_and_taut(design, theta_L, delta, scale):
    """A cheap per-pose function for the engine tests: dict of arrays of several shapes/dtypes."""
    p, R = tz.tip_pose(design, theta_L, delta)
    return {"p": scale * p, "R": R, "n_taut": jnp.sum(tz.tension_mask(design, delta) > 0.5)}


def direct(design, th, de, scale):
    """The same grid by one plain jitted vmap (no chunks, no padding)."""
    out = jax.jit(tz.over_grid(tip_and_taut))(design, jnp.asarray(th), jnp.asarray(de), scale)
    return {k: np.asarray(v) for k, v in out.items()}


def test_grid_deg_is_the_papers_inclusive_grid():
    np.testing.assert_allclose(grid_deg(85, 5), np.arange(0, 90, 5.0))
    assert grid_deg(360, 2.5).size == 145 and grid_deg(360, 2.5)[-1] == 360.0
    assert grid_deg(85, 7)[-1] == 84.0
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="positive"):
            grid_deg(85, bad)


@pytest.mark.parametrize("chunk", [7, 64, 10_000])
def test_chunks_and_padding_change_nothing(d3, chunk):
    th, de = rad(grid_deg(85, 17)), rad(grid_deg(360, 30))
    res = sweep_grid(tip_and_taut, d3, th, de, 2.0, chunk_size=chunk, quiet=True)
    ref = direct(d3, th, de, 2.0)
    assert set(res) == set(ref)
    for k in ref:
        assert res[k].shape == ref[k].shape == (th.size, de.size) + ref[k].shape[2:]
        # equal up to the rounding of differently shaped compiled code
        np.testing.assert_allclose(res[k], ref[k], rtol=1e-14, atol=1e-15)
    np.testing.assert_array_equal(res["n_taut"], ref["n_taut"])
    assert res["n_taut"].dtype == ref["n_taut"].dtype


@pytest.mark.parametrize("in_flight", [1, 2, 5])
def test_chunks_in_flight_change_nothing(d3, in_flight, monkeypatch):
    from tension_zones.analysis import _sweep as sweep

    th, de = rad(grid_deg(85, 17)), rad(grid_deg(360, 30))
    ref = sweep_grid(tip_and_taut, d3, th, de, 2.0, chunk_size=7, quiet=True)
    monkeypatch.setattr(sweep, "IN_FLIGHT", in_flight)
    res = sweep_grid(tip_and_taut, d3, th, de, 2.0, chunk_size=7, quiet=True)
    for k in ref:  # same compiled program, same pose positions: bit for bit
        np.testing.assert_array_equal(res[k], ref[k])


def test_flat_poses_and_keep(d4):
    rng = np.random.default_rng(0)
    th, de = rng.uniform(0, 1.5, 50), rng.uniform(0, 6.3, 50)
    res = sweep_poses(tip_and_taut, d4, th, de, 1.0, chunk_size=16, quiet=True, keep=["p"])
    assert list(res) == ["p"] and res["p"].shape == (50, 3)
    for i in (0, 17, 49):
        np.testing.assert_allclose(res["p"][i], tz.tip_pose(d4, th[i], de[i])[0], rtol=1e-15)


def test_no_recompile_when_only_values_change(d3):
    th, de = rad(grid_deg(85, 17)), rad(grid_deg(360, 30))
    sweep_grid(tip_and_taut, d3, th, de, 1.0, chunk_size=32, quiet=True)
    n0 = compiled_chunk_count()
    other = d3.replace(length=33.0, pitch_radius=1.5, wire_angles=rad([5.0, 100.0, 230.0]))
    res = sweep_grid(tip_and_taut, other, th + 0.01, de, 3.0, chunk_size=32, quiet=True)
    assert compiled_chunk_count() == n0
    np.testing.assert_allclose(res["p"], direct(other, th + 0.01, de, 3.0)["p"], rtol=1e-14)
    # a grid of other axis lengths: the same program
    th2, de2 = rad(grid_deg(80, 4)), rad(grid_deg(350, 50))
    res = sweep_grid(tip_and_taut, other, th2, de2, 3.0, chunk_size=32, quiet=True)
    assert compiled_chunk_count() == n0
    np.testing.assert_allclose(res["p"], direct(other, th2, de2, 3.0)["p"], rtol=1e-14)


@pytest.mark.parametrize("chunk", [5, 13])
def test_grid_axes_longer_than_a_chunk(d3, chunk):
    """Axes longer than a chunk take the host-side path: same poses, same results."""
    th, de = rad(grid_deg(85, 5)), rad(grid_deg(360, 30))  # 18 x 13 poses
    res = sweep_grid(tip_and_taut, d3, th, de, 2.0, chunk_size=chunk, quiet=True)
    ref = direct(d3, th, de, 2.0)
    for k in ref:
        np.testing.assert_allclose(res[k], ref[k], rtol=1e-14, atol=1e-15)


def test_bad_input_is_a_clear_error(d3):
    th, de = rad(grid_deg(85, 17)), rad(grid_deg(360, 30))
    with pytest.raises(ValueError, match="chunk_size must be a positive integer"):
        sweep_grid(tip_and_taut, d3, th, de, 1.0, chunk_size=0)
    with pytest.raises(ValueError, match="keep names unknown output"):
        sweep_grid(tip_and_taut, d3, th, de, 1.0, keep=["nope"], quiet=True)
    with pytest.raises(ValueError, match="1-D"):
        sweep_grid(tip_and_taut, d3, th[:, None], de, 1.0)
    with pytest.raises(ValueError, match="equal length"):
        sweep_poses(tip_and_taut, d3, th, de, 1.0)
    with pytest.raises(TypeError, match="must return a dict"):
        sweep_grid(lambda d, t, x: t, d3, th, de, quiet=True)
    with pytest.raises(TypeError, match="Design"):
        sweep_grid(tip_and_taut, {"n_wires": 3}, th, de, 1.0)


def test_progress_bar_on_long_sweeps_only(d3, capsys):
    th, de = rad(grid_deg(85, 5)), rad(grid_deg(360, 10))
    sweep_grid(tip_and_taut, d3, th, de, 1.0, chunk_size=64, desc="tiny")
    assert "tiny" in capsys.readouterr().err  # several chunks: a bar
    sweep_grid(tip_and_taut, d3, th, de, 1.0, chunk_size=64, quiet=True)
    sweep_grid(tip_and_taut, d3, th, de, 1.0, chunk_size=10_000)  # one chunk: no bar
    assert capsys.readouterr().err == ""


SHARDED = textwrap.dedent("""
    import jax, numpy as np
    import tension_zones as tz
    from tension_zones.analysis._metrics import pose_metrics
    from tension_zones.analysis._sweep import sweep_grid, grid_deg
    assert len(jax.devices()) == 4, jax.devices()
    d = tz.Design(4, 20.0, 2.0, wire_angles=np.radians([0.0, 80.0, 180.0, 260.0]))
    th, de = np.radians(grid_deg(85, 5)), np.radians(grid_deg(360, 2.5))
    one = sweep_grid(pose_metrics, d, th, de, 0.4, chunk_size=250, devices=jax.devices()[:1], quiet=True)
    four = sweep_grid(pose_metrics, d, th, de, 0.4, chunk_size=250, quiet=True)
    assert set(one) == set(four)
    for k in one:
        assert np.array_equal(one[k], four[k]), k
    print("identical", len(one))
    # a robot's sweep runs on one device (XLA:CPU deadlocks sharding it over host devices)
    from tension_zones.analysis import config_metrics, config_samples, sweep_configs
    robot = tz.Robot.from_json(tz.example_path("ftdcr_v4/design.json"))
    B = config_samples(3, 300, 90.0)
    default = sweep_configs(config_metrics, robot, B, 0.4, chunk_size=128, quiet=True)
    first = sweep_configs(config_metrics, robot, B, 0.4, chunk_size=128, devices=jax.devices()[:1], quiet=True)
    for k in first:
        assert np.array_equal(default[k], first[k]), k
    try:
        sweep_configs(config_metrics, robot, B, 0.4, devices=jax.devices(), quiet=True)
    except ValueError as e:
        assert "one CPU device" in str(e), e
        print("robot on one device")
    # so does an exploration of robots (each chunk's designs on one device)
    import tempfile
    seg = lambda L, r: {"length_mm": L, "n_wires": [3], "pitch_radius_mm": r}
    space = tz.parse_space({"segments": [seg(40.0, [2.0, 4.0]), seg(30.0, 2.0), seg(30.0, 2.0)], "samples": 64,
                            "sample": {"method": "halton", "designs": 4}})
    with tempfile.TemporaryDirectory() as d:
        tz.explore(space, d + "/o", quiet=True)
        t = np.load(d + "/o/table.npz")
        assert t["design"].size == 4 and np.all(np.isfinite(t["dp_max_reduced_worst"]))
    print("robots explored")
""")


def test_a_robot_sweep_takes_the_chunk_its_function_asks_for(monkeypatch):
    """``config_metrics`` asks for :data:`METRICS_CHUNK` configurations per call up to
    ``BOX_VERTICES_MAX`` wires and :data:`ROBOT_CHUNK` beyond; a function that says nothing gets
    ``ROBOT_CHUNK``. The sweep at its default chunk equals the measures evaluated one by one."""
    from conftest import two_segments

    from tension_zones.analysis import _sweep, config_metrics, config_samples, sweep_configs
    from tension_zones.analysis._chain import BOX_VERTICES_MAX, METRICS_CHUNK

    robot = two_segments()
    many = tz.Robot([tz.Design(8, 40.0, 3.0), tz.Design(BOX_VERTICES_MAX - 7, 50.0, 2.5)])
    assert METRICS_CHUNK > _sweep.ROBOT_CHUNK
    assert _sweep.robot_chunk(config_metrics, robot) == METRICS_CHUNK
    assert _sweep.robot_chunk(config_metrics, many) == _sweep.ROBOT_CHUNK
    assert _sweep.robot_chunk(lambda r, B: {"B": B}, robot) == _sweep.ROBOT_CHUNK

    sizes, run = [], _sweep._eval_chunk_jit
    monkeypatch.setattr(
        _sweep, "_eval_chunk_jit", lambda fn, d, poses, *a: sizes.append(poses[0].shape[0]) or run(fn, d, poses, *a)
    )
    B = config_samples(2, 300, 60.0)
    res = sweep_configs(config_metrics, robot, B, 0.4, quiet=True)
    assert sizes == [METRICS_CHUNK]
    for i in (0, 151, 299):
        ref = config_metrics(robot, B[i], 0.4)
        for k, v in ref.items():
            np.testing.assert_allclose(res[k][i], v, rtol=1e-12, atol=1e-12, err_msg=k)


@pytest.mark.slow
def test_sharded_over_four_devices_gives_identical_results(default_codegen_env):
    env = default_codegen_env(
        "--xla_force_host_platform_device_count=4",
        PYTHONPATH=os.pathsep.join([str(__import__("pathlib").Path(__file__).parents[1])] + sys.path),
    )
    r = subprocess.run(
        [sys.executable, "-c", SHARDED], capture_output=True, text=True, env=env, timeout=600, check=False
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "identical 17" in r.stdout and "robot on one device" in r.stdout and "robots explored" in r.stdout


# ------------------------------------------------------------------------------------------------
# Command line
# ------------------------------------------------------------------------------------------------
def test_cli_sweep_writes_the_issue_arrays(tmp_path, capsys):
    out = tmp_path / "s.npz"
    assert (
        main(
            [
                "sweep",
                "--wires",
                "3",
                "--length",
                "20",
                "--pitch-radius",
                "2",
                "--dq",
                "0.4",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    assert capsys.readouterr().out == ""
    z = np.load(out)
    names = ["theta_L_deg", "delta_deg", "n_taut"] + [
        f"{m}_{mode}"
        for mode in ("full", "reduced")
        for m in ("kci_v", "kci_w", "sigma_min_v", "sigma_min_w", "dp_max", "dw_max")
    ]
    for name in names:
        assert z[name].shape == (18, 145), name
    np.testing.assert_array_equal(z["theta_L_deg"][:, 0], np.arange(0, 90, 5.0))
    np.testing.assert_array_equal(z["delta_deg"][0], np.arange(0, 362.5, 2.5))
    # values are the independent reference's at those poses (tests/test_metrics.py)
    for i, j in ((11, 27), (3, 100), (17, 144)):
        for mode in ("full", "reduced"):
            ref = ref_measures(
                20.0,
                2.0,
                rad([0.0, 120.0, 240.0]),
                rad(z["theta_L_deg"][i, j]),
                rad(z["delta_deg"][i, j]),
                0.4,
                mode == "reduced",
            )
            for k in MEASURES:
                assert z[f"{k}_{mode}"][i, j] == pytest.approx(ref[k], rel=1e-9, abs=1e-12)


def test_cli_sweep_uneven_angles_steps_and_dq(tmp_path):
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    common = [
        "sweep",
        "--wires",
        "4",
        "--length",
        "30",
        "--pitch-radius",
        "3",
        "--angles",
        "0,80,180,260",
        "--theta-step",
        "17",
        "--delta-step",
        "45",
        "--quiet",
    ]
    assert main(common + ["--dq", "0.2", "--out", str(a)]) == 0
    n_compiled = compiled_chunk_count()
    assert main(common + ["--dq", "1.0", "--out", str(b)]) == 0
    assert compiled_chunk_count() == n_compiled  # a new dq is a new value, not a new program
    za, zb = np.load(a), np.load(b)
    assert za["n_taut"].shape == (6, 9)
    np.testing.assert_allclose(zb["dp_max_reduced"], 5 * za["dp_max_reduced"], rtol=1e-12)
    np.testing.assert_array_equal(zb["kci_v_reduced"], za["kci_v_reduced"])
    assert za["n_taut"][0, 2] == 1  # delta = 90 deg is a zone end of wire 1


@pytest.mark.parametrize(
    "extra, needle",
    [
        (["--length", "-1"], "length must be positive"),
        (["--dq", "0"], "--dq must be a positive number"),
        (["--theta-step", "-5"], "--theta-step must be a positive number"),
        (["--wires", "2"], "n_wires must be at least 3"),
        (["--angles", "0,1"], "--angles has 2 values"),
    ],
)
def test_cli_sweep_errors_are_one_line(tmp_path, capsys, extra, needle):
    out = tmp_path / "s.npz"
    argv = ["sweep", "--wires", "3", "--length", "20", "--pitch-radius", "2", "--out", str(out)]
    for k in range(0, len(extra), 2):  # later flags override the defaults above
        if extra[k] in argv:
            argv[argv.index(extra[k]) + 1] = extra[k + 1]
        else:
            argv += extra[k : k + 2]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


def test_cli_sweep_bad_out_path(tmp_path, capsys):
    argv = ["sweep", "--wires", "3", "--length", "20", "--pitch-radius", "2", "--out"]
    assert main(argv + [str(tmp_path / "s.csv")]) == 2
    assert "must end in .npz" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_sweep_32_wires_within_a_minute(tmp_path):
    """A sweep of many wires stays quick: the program does not grow with the wire count (per-wire
    work on arrays, test_metrics) and the chunk shrinks with it (default_chunk)."""
    import time

    from tension_zones.analysis._sweep import default_chunk

    assert default_chunk(8) == 1 << 14 and default_chunk(32) == 1 << 10 and default_chunk(1000) == 256
    out = tmp_path / "s32.npz"
    t0 = time.perf_counter()
    assert main(["sweep", "--wires", "32", "--length", "20", "--pitch-radius", "2", "--out", str(out), "--quiet"]) == 0
    assert time.perf_counter() - t0 < 60
    z = np.load(out)
    assert z["dp_max_reduced"].shape == (18, 145) and np.all(np.isfinite(z["dp_max_reduced"]))
    assert np.all(z["n_taut"][:, 1:-1] >= 15)  # about half of 32 even wires are taut
    ref = pose_metrics_at(tz.Design(32, 20.0, 2.0), rad(z["theta_L_deg"][7, 33]), rad(z["delta_deg"][7, 33]))
    for k, v in ref.items():
        assert z[k][7, 33] == pytest.approx(float(v), rel=1e-12, abs=1e-15), k


def pose_metrics_at(design, theta_L, delta):
    from tension_zones.analysis._metrics import pose_metrics

    return pose_metrics(design, theta_L, delta, 0.4)
