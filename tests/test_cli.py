"""The command line: outputs, and one-line errors that lose nothing."""

import json
import subprocess
import sys

import jax
import numpy as np
import pytest

import tension_zones as tz
from tension_zones.cli import main


def test_maps_writes_png_and_prints_table(tmp_path, capsys):
    out = tmp_path / "m.png"
    assert main(["maps", "--wires", "3", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert out.stat().st_size > 10_000
    assert "(30, 90)" in text and "1, 3" in text


def test_maps_uneven_angles_in_degrees(tmp_path, capsys):
    out = tmp_path / "m.png"
    assert main(["maps", "--wires", "4", "--angles", "0,80,180,260", "--out", str(out)]) == 0
    assert "{10}" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["maps", "--wires", "2"], "n_wires must be at least 3"),
        (["maps", "--wires", "3", "--angles", "0,1"], "--angles has 2 values"),
        (["maps", "--wires", "3", "--angles", "0,x,2"], "--angles must be comma-separated"),
        (["maps", "--wires", "3", "--angles", "0,0,90"], "coincident wires 1 and 2"),
    ],
)
def test_errors_are_one_line(tmp_path, capsys, argv, needle):
    out = tmp_path / "m.png"
    assert main(argv + ["--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


def test_bad_out_paths(tmp_path, capsys):
    assert main(["maps", "--wires", "3", "--out", str(tmp_path / "nope" / "m.png")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["maps", "--wires", "3", "--out", str(tmp_path / "m.jpg")]) == 2
    assert "must end in .png" in capsys.readouterr().err


@pytest.mark.slow
def test_console_script_runs(tmp_path):
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "tension_zones.cli",
            "maps",
            "--wires",
            "5",
            "--out",
            str(tmp_path / "m5.png"),
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    assert "wires" in r.stdout and r.stderr == ""


@pytest.mark.slow
def test_sweep_compliance_adds_the_statics_arrays(tmp_path):
    import numpy as np

    import tension_zones as tz

    out = tmp_path / "c.npz"
    assert (
        main(
            [
                "sweep",
                "--wires",
                "4",
                "--length",
                "20",
                "--pitch-radius",
                "2",
                "--compliance",
                "--wire-stiffness",
                "75",
                "--backbone-EI",
                "1200",
                "--load",
                "5,0,0",
                "--preload",
                "5",
                "--quiet",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    z = np.load(out)
    assert z["theta_L_deg"].shape == (10, 25)  # the paper's Sec. 6.2 grid by default
    np.testing.assert_allclose(z["theta_L_deg"][:, 0], np.linspace(89, 45, 10))
    for k in (
        "deflection_mm_full",
        "deflection_mm_reduced",
        "deflection_deg_full",
        "deflection_deg_reduced",
        "n_taut_statics",
        "feasible",
        "dp_max_reduced",
        "kci_v_full",
    ):
        assert z[k].shape == (10, 25), k
    assert z["tensions"].shape == (10, 25, 4)
    # with a preload every wire is taut: reduced equals traditional
    np.testing.assert_allclose(z["deflection_mm_reduced"], z["deflection_mm_full"], rtol=1e-9)
    d = tz.Design(4, 20.0, 2.0, wire_stiffness=75.0, backbone_EI=1200.0, preload=5.0)
    ref = tz.compliance_pose(
        d, np.radians(z["theta_L_deg"][3, 7]), np.radians(z["delta_deg"][3, 7]), np.array([5.0, 0, 0])
    )
    np.testing.assert_allclose(z["deflection_mm_reduced"][3, 7], ref["deflection_mm_reduced"], rtol=1e-12)


@pytest.mark.parametrize(
    "extra, needle",
    [
        (["--compliance"], "--compliance needs --wire-stiffness, --backbone-EI, --load"),
        (["--load", "1,2,3"], "go with --compliance"),
        (["--compliance", "--wire-stiffness", "75", "--backbone-EI", "1200", "--load", "1,x,3"], "--load must be"),
        (
            ["--compliance", "--wire-stiffness", "-75", "--backbone-EI", "1200", "--load", "1,0,0"],
            "wire_stiffness must be positive",
        ),
    ],
)
def test_sweep_compliance_errors(tmp_path, capsys, extra, needle):
    out = tmp_path / "c.npz"
    argv = ["sweep", "--wires", "3", "--length", "20", "--pitch-radius", "2", "--out", str(out)]
    assert main(argv + extra) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
    assert not out.exists()


LAZY = """
import sys, time
t0 = time.perf_counter()
from tension_zones.cli import main
for argv in (["--help"], ["maps", "--help"], ["sweep", "--help"], ["optimize", "--help"],
             ["reproduce", "--help"], ["calibrate", "--help"]):
    try:
        main(argv)
    except SystemExit as e:
        assert e.code == 0, (argv, e.code)
import tension_zones as tz
assert "jax" not in sys.modules, sorted(m for m in sys.modules if m.startswith("jax"))
assert "Design" in dir(tz) and "Design" in tz.__all__
print("help-seconds", time.perf_counter() - t0, file=sys.stderr)
import jax.numpy as jnp  # imported after the package: float64 is on before any array is made
assert jnp.ones(1).dtype == jnp.float64
assert tz.Design(3, 20.0, 2.0).length.dtype == jnp.float64
for name in tz.__all__:
    getattr(tz, name)
print("lazy ok")
"""


@pytest.mark.slow
def test_help_and_import_do_not_import_jax():
    r = subprocess.run([sys.executable, "-c", LAZY], capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip().endswith("lazy ok")


@pytest.mark.parametrize("n", [16, 64])
def test_maps_of_many_wires_stay_legible(tmp_path, n):
    """Maps of many wires stay legible (not a black band of labels): above plots.LABEL_MAX_WIRES the
    sectors carry at most their taut count, and only every few rings is numbered."""
    import matplotlib.pyplot as plt

    import tension_zones as tz
    from tension_zones.plots import LABEL_MAX_WIRES, plot_tension_map

    assert n > LABEL_MAX_WIRES
    fig, ax = plt.subplots()
    plot_tension_map(tz.tension_map(tz.Design(n, 20.0, 2.0)), ax=ax)
    labels = [t.get_text() for t in ax.texts]
    plt.close(fig)
    assert len(labels) <= 40, len(labels)  # before: 204 at 64 wires (every sector, ray and ring)
    assert all("," not in t for t in labels)  # no lists of wires
    assert main(["maps", "--wires", str(n), "--out", str(tmp_path / "m.png"), "--quiet"]) == 0


def test_sweep_takes_a_robot_of_two_segments_from_a_design_file(tmp_path):
    """Halton configurations of the shipped two-segment robot; every array is the robot's own
    ``config_metrics`` at the configurations the file holds."""
    out = tmp_path / "two.npz"
    design = tz.example_path("design/two_segments.design.json")
    main(["sweep", "--design", str(design), "--samples", "300", "--max-bend", "60", "--out", str(out), "--quiet"])
    res = np.load(out)
    assert res["B"].shape == (300, 2, 2) and np.all(res["bend_deg"] <= 60 + 1e-9)
    robot = tz.Robot.from_json(design)
    want = jax.jit(jax.vmap(tz.config_metrics, (None, 0, None)))(robot, res["B"][:5], 0.4)
    for k, v in want.items():
        np.testing.assert_allclose(res[k][:5], np.asarray(v), rtol=1e-12, err_msg=k)


def test_sweep_of_a_robot_with_compliance_takes_the_files_stiffness(tmp_path):
    out = tmp_path / "two.npz"
    design = tz.example_path("design/two_segments.design.json")
    argv = ["sweep", "--design", str(design), "--samples", "64", "--compliance", "--load", "0,0,-0.5"]
    main([*argv, "--out", str(out), "--quiet"])
    res = np.load(out)
    w = np.array([0.0, 0.0, -0.5, 0.0, 0.0, 0.0])
    want = jax.jit(jax.vmap(tz.config_compliance, (None, 0, None)))(tz.Robot.from_json(design), res["B"][:3], w)
    for k, v in want.items():
        np.testing.assert_allclose(res[k][:3], np.asarray(v), rtol=1e-12, err_msg=k)
    assert np.all(res["feasible"]) and np.all(res["deflection_mm_reduced"] > 0)


def test_sweep_of_a_one_segment_design_file_is_the_segments_grid(tmp_path, capsys):
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    design = tz.example_path("synthetic/nominal_3w.design.json")
    seg = tz.Robot.from_json(design).segments[0]
    main(["sweep", "--design", str(design), "--theta-step", "17", "--delta-step", "30", "--out", str(a), "--quiet"])
    angles = ",".join(f"{x:.12g}" for x in np.degrees(np.asarray(seg.wire_angles)))
    flags = [
        "--wires",
        "3",
        "--length",
        f"{float(seg.length):.17g}",
        "--pitch-radius",
        f"{float(seg.pitch_radius):.17g}",
    ]
    main(["sweep", *flags, "--angles", angles, "--theta-step", "17", "--delta-step", "30", "--out", str(b), "--quiet"])
    ra, rb = np.load(a), np.load(b)
    for k in rb.files:
        np.testing.assert_allclose(ra[k], rb[k], rtol=1e-12, err_msg=k)


def test_maps_of_a_robot_draw_each_segment_with_the_others_straight_and_bent(tmp_path, capsys):
    out = tmp_path / "robot.png"
    design = tz.example_path("design/two_segments.design.json")
    assert main(["maps", "--design", str(design), "--bend", "30", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.count("delta (deg)") == 4 and "segment 2 of 2, the others bent 30 deg" in text
    assert out.stat().st_size > 50_000


def test_optimize_starts_from_a_design_file_and_refuses_a_mismatch_in_one_line(tmp_path, capsys):
    """``optimize --design``: the robot's values where the scenario leaves them out, the robot itself as
    ``start`` in result.json and on the first line; a scenario of another segment count: one line."""
    design = tz.example_path("design/two_segments.design.json")
    scenario = tmp_path / "s.json"
    task = {"max_bend_deg": 40.0, "samples": 16, "weights": {"deflection": 0.0}, "optimizer": {"starts": 1, "steps": 2}}
    scenario.write_text(json.dumps({**task, "pitch_radius_mm": [1.0, 3.0]}))
    argv = ["optimize", "--scenario", str(scenario), "--design", str(design), "--quiet"]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 0
    assert capsys.readouterr().out.startswith(f"start ({design}): objective ")
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    assert res["start"]["design"] == tz.Robot.from_json(design).to_dict()
    scenario.write_text(json.dumps({**task, "segments": [{}]}))
    assert main([*argv, "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err
    assert err == (
        "tension-zones: error: scenario key 'segments': has 1 entry; the design file has 2 segment(s): one "
        "entry each, or leave it out\n"
    )
    assert not (tmp_path / "o2").exists()


def test_optimize_takes_the_shipped_scenario_of_two_segments(tmp_path, capsys):
    out = tmp_path / "opt"
    scenario = tz.example_path("design/two_segments.scenario.json")
    assert main(["optimize", "--scenario", str(scenario), "--out", str(out), "--quiet"]) == 0
    assert capsys.readouterr().out.startswith("best: 4+4 wires, r = 4, ")
    res = json.loads((out / "result.json").read_text())
    assert res["segments"] == 2 and [r["n_wires"] for r in res["per_wire_count"]] == [[4, 3], [4, 4]]
    assert not res["per_wire_count"][0]["feasible"]  # three even wires leave sectors of one taut wire
    assert res["best"]["worst_deflection_mm"] > 0 and res["best"]["statics_infeasible_poses"] == 0
    robot = tz.Robot.from_dict(res["best"]["design"])
    assert robot.n_wires_per_segment == (4, 4) and float(robot.segments[0].pitch_radius) == 4.0
    for name in ("tradeoff.png", "convergence.png"):
        assert (out / name).stat().st_size > 10_000, name
