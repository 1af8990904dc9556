"""The calibration loop on sets from the project's own generator (tests/simulator.py).

Each library effect alone, pairs, no effect (nothing may be added), an effect outside the library
(structure must be reported, no effect claimed), tracker glitches (the robust loss keeps the fit),
and the command line end to end. Sets are small (240 samples) so the whole file runs in about a minute.
"""

import dataclasses
import json

import numpy as np
import pytest
from simulator import Truth, write_set

import tension_zones as tz
from tension_zones.calibration import calibrate, read_csv, rmse
from tension_zones.cli import main

ALONE = {
    "backlash": Truth(play=(0.2, 0.3, 0.15)),
    "friction": Truth(friction=0.2),
    "wire_angle_offset": Truth(angle_offsets_deg=(4.0, -3.0, 5.0)),
    "wire_stiffness": Truth(stiffness_factors=(0.6, 1.0, 1.5)),
    "preload": Truth(d_preload=(3.0, -1.5, 0.0)),
    "tip_force": Truth(tip_force=(0.3, -0.4, -0.8)),
    "registration": Truth(rotation_deg=(1.0, -0.8, 1.5), translation=(0.4, -0.3, 0.5)),
    "geometry": Truth(d_length=0.4, d_radius=0.15),
}


def run(tmp_path, name, truth, seed=1, **kw):
    csv, dj = write_set(tmp_path, name, truth, 240, seed=seed)
    design = tz.Design.from_json(dj)
    rep = calibrate(read_csv(csv, design.n_wires, float(design.length)), design, **kw).to_json()
    screening(rep)
    return rep


def screening(rep) -> int:
    """Where a round screened its candidates (short refits), only those whose short refit lowered the
    held-out error by a quarter of the drop the full refit needs went on to full refits. Returns how
    many candidates were screened."""
    count = 0
    for rd in rep["rounds"]:
        sc = {c["name"]: c for c in rep["candidates"] if c["round"] == rd["round"] and "screened_rmse_mm" in c}
        count += len(sc)
        for t in rd["tried"]:
            assert not sc.get(t["name"], {}).get("screened_out", False)
        if not rep["robust"]:  # (robust decisions leave glitches out of the held-out error)
            for c in sc.values():
                assert c["screened_out"] == (c["screened_drop"] < c["screened_needed"])
                if c["screened_rmse_mm"] >= rd["rmse_held_out_mm"]:
                    assert c["screened_out"]
    return count


def names(report):
    return [e["name"] for e in report["effects"]]


@pytest.mark.parametrize("effect", list(ALONE))
def test_each_effect_alone_is_found(tmp_path, effect):
    rep = run(tmp_path, effect, ALONE[effect])
    assert names(rep) == [effect]
    assert rep["rmse_before_mm"] > 1.5 * rep["noise_floor_mm"]  # the effect mattered
    assert rep["rmse_after_mm"] < 1.3 * rep["noise_floor_mm"]
    assert not rep["unexplained_structure"]


def test_one_preload_on_every_wire_is_named_pretension_its_special_case(tmp_path):
    """A preload common to a segment's wires fits per wire as well as per segment; the per-wire
    effect's two extra parameters buy no significant drop over its special case, so the pretension is
    named, and the round says why (on this set the per-wire refit is the lower by a hair)."""
    from tension_zones.calibration._report import _md_round

    rep = run(tmp_path, "pretension", Truth(d_preload=(2.0, 2.0, 2.0)), seed=2)
    assert names(rep) == ["pretension"]
    rd = rep["rounds"][0]
    nested = rd["nested"]
    assert (nested["kept"], nested["over"], nested["extra"]) == ("pretension", "preload", 2)
    assert nested["sse_drop"] < nested["needed"]
    tried = {t["name"]: t for t in rd["tried"]}
    assert tried["preload"]["rmse_held_out_mm"] <= tried["pretension"]["rmse_held_out_mm"]
    assert rep["rmse_after_mm"] < 1.3 * rep["noise_floor_mm"] and not rep["unexplained_structure"]
    assert any("pretension is a special case of preload" in line for line in _md_round(rep, rd))


def test_the_final_refit_takes_every_sample_of_the_data_file_and_nothing_of_the_validation_file(tmp_path):
    """The held-out errors are the training part's fit's (out of sample); the chosen model is then
    refitted on every sample of the data file, which gives the parameters and the validation error;
    the validation file never moves it."""
    csv, dj = write_set(tmp_path, "t", ALONE["backlash"], 240, seed=1)
    vcsv, _ = write_set(tmp_path, "v", ALONE["backlash"], 120, seed=2)
    design = tz.Design.from_json(dj)
    data, val = (read_csv(p, design.n_wires, float(design.length)) for p in (csv, vcsv))
    res = calibrate(data, design, validate=val)
    rep, pb, act = res.to_json(), res.problem, res.active
    assert names(rep) == ["backlash"]
    r_sel, r_fin = pb.residuals(res.theta_selected, act), pb.residuals(res.theta_after, act)
    assert rep["rmse_after_mm"] == pytest.approx(rmse(r_sel[res.held]), rel=1e-12)
    assert rep["rmse_validate_mm"] == pytest.approx(rmse(r_fin[res.val]), rel=1e-12)
    assert rep["steps"][-1]["rmse_validate_mm"] == rep["rmse_validate_mm"]
    assert rep["steps"][-1]["rmse_held_out_mm"] == rep["rmse_after_mm"]  # the selected model, not refitted
    assert rep["steps"][0]["rmse_held_out_mm"] == pytest.approx(rep["rmse_before_mm"], rel=1e-12)
    assert rep["model"]["theta"] == res.theta_after.tolist()
    fitted = res.train | res.held
    assert rep["rmse_refit_mm"] == pytest.approx(rmse(r_fin[fitted]), rel=1e-12)
    assert rmse(r_fin[fitted]) <= rmse(r_sel[fitted]) and rmse(r_fin[res.held]) < rmse(r_sel[res.held])
    # a validation file measured 5 mm off changes its error, not the model; and a worker process
    # running the loop's independent fits (calibration/_fits.py) changes nothing: every decision,
    # error and parameter of the report is the same, bit for bit
    moved = calibrate(data, design, validate=dataclasses.replace(val, p=val.p + 5.0), workers=1)
    assert [e.name for e in moved.effects] == ["backlash"]
    assert [e.to_dict() for e in res.effects] == rep["effects"] and res.effects[0].params_std is not None
    assert moved.theta_after.tolist() == res.theta_after.tolist()
    assert moved.rmse["validate"] > res.rmse["validate"] + 3.0
    assert screening(rep) > 0  # (the round's short refits ran, on both processes)
    assert _without_validation(moved.to_json()) == _without_validation(rep)


def _without_validation(rep: dict) -> dict:
    """A report without what depends on the validation file (or on the clock)."""
    out = {k: v for k, v in rep.items() if "validate" not in k and k not in ("baselines", "seconds")}
    out["steps"] = [{k: v for k, v in s.items() if "validate" not in k} for s in rep["steps"]]
    for s in out["steps"]:
        s.get("rmse_by_family_mm", {}).pop("validate", None)
    return out


def test_recovered_values(tmp_path):
    rep = run(tmp_path, "bl", ALONE["backlash"])
    play = list(rep["effects"][0]["params"].values())
    np.testing.assert_allclose(play, [0.2, 0.3, 0.15], atol=0.03)
    std = np.array(list(rep["effects"][0]["params_std"].values()))
    assert np.all(std > 0) and np.all(np.abs(np.subtract(play, [0.2, 0.3, 0.15])) < 5 * std + 1e-3)
    rep = run(tmp_path, "geo", ALONE["geometry"])
    p = rep["effects"][0]["params"]
    assert abs(p["length_mm"] - 20.4) < 0.1 and abs(p["pitch_radius_mm"] - 2.15) < 0.05


@pytest.mark.parametrize(
    "truth, expected",
    [
        (
            Truth(play=(0.25, 0.25, 0.25), rotation_deg=(0.0, 1.5, 0.0), translation=(0.5, 0.0, -0.4)),
            {"backlash", "registration"},
        ),
        (Truth(n_wires=4, angle_offsets_deg=(5.0, 0.0, -4.0, 3.0), friction=0.15), {"wire_angle_offset", "friction"}),
    ],
    ids=["backlash+registration", "4w-angles+friction"],
)
def test_pairs_are_found(tmp_path, truth, expected):
    rep = run(tmp_path, "pair", truth)
    assert set(names(rep)) == expected
    assert rep["rmse_after_mm"] < 1.3 * rep["noise_floor_mm"]
    assert not rep["unexplained_structure"]


@pytest.mark.parametrize("seed", [2, 3])
def test_no_effect_nothing_added(tmp_path, seed):
    rep = run(tmp_path, "none", Truth(), seed=seed)
    assert names(rep) == []
    assert "routing_twist" not in {c["name"] for c in rep["candidates"]}  # nothing to twist in one segment
    floor = 0.05 * np.sqrt(3)  # the simulated noise
    assert rep["rmse_after_mm"] < 1.15 * floor
    assert not rep["unexplained_structure"]
    # the floor is estimated from the data (repeated samples), not assumed
    assert abs(rep["noise_floor_mm"] / floor - 1) < 0.2


def test_effect_outside_library_reports_structure(tmp_path):
    # a periodic tracker drift along the acquisition order: nothing in the library can produce it
    rep = run(tmp_path, "drift", Truth(drift_mm=0.25))
    assert screening(rep) > 4  # (more than four significant candidates in a round: screened)
    assert rep["unexplained_structure"] is True
    assert names(rep) == []  # no wrong claim
    assert rep["structure"]["order"]["z"] > 4


def test_a_large_effect_outside_the_library_is_not_named_far_above_the_floor(tmp_path):
    """Nine noise floors above the floor the share a refit needs has fallen, but not below what a
    library effect explains of structure the library lacks (``MIN_SHARE``): the pattern's rotation
    explains 15 % of a 1 mm drift and is not named."""
    rep = run(tmp_path, "drift", Truth(drift_mm=1.0))
    assert rep["rmse_after_mm"] > 8 * rep["noise_floor_mm"]
    assert names(rep) == [] and rep["unexplained_structure"] is True


def test_glitches_robust_loss_keeps_the_fit(tmp_path):
    truth = Truth(play=(0.2, 0.3, 0.15), glitches=6)
    rob = run(tmp_path, "glitch", truth, robust=True)
    assert names(rob)[0] == "backlash"
    np.testing.assert_allclose(list(rob["effects"][0]["params"].values()), [0.2, 0.3, 0.15], atol=0.04)
    ls = run(tmp_path, "glitch", truth, robust=False)
    ls_play = list(ls["effects"][0]["params"].values()) if ls["effects"] else [0, 0, 0]
    rob_play = list(rob["effects"][0]["params"].values())
    # least squares is pulled by the glitches more than the robust fit
    assert (
        np.abs(np.subtract(rob_play, [0.2, 0.3, 0.15])).max()
        <= np.abs(np.subtract(ls_play, [0.2, 0.3, 0.15])).max() + 1e-3
    )


def test_cli_end_to_end(tmp_path, capsys):
    csv, dj = write_set(tmp_path, "reg", ALONE["registration"], 240, seed=4)
    lines = csv.read_text().splitlines()
    cells = lines[100].split(",")
    cells[-4] = "nan"  # pz of data row 100
    lines[100] = ",".join(cells)
    csv.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    assert main(["calibrate", str(csv), "--design", str(dj), "--out", str(out), "--quiet"]) == 2
    assert "column 'pz', row 100" in capsys.readouterr().err
    assert main(["calibrate", str(csv), "--design", str(dj), "--out", str(out), "--quiet", "--drop-bad"]) == 0
    text = capsys.readouterr().out
    assert "effects added: registration" in text and "dropped rows: 1" in text
    rep = json.loads((out / "report.json").read_text())
    assert rep["dropped_rows"] == 1 and rep["dropped"][0]["row"] == 100 and rep["n_samples"] == 239
    for key in (
        "rmse_declared_mm",
        "rmse_before_mm",
        "rmse_after_mm",
        "effects",
        "candidates",
        "noise_floor_mm",
        "unexplained_structure",
        "parameters",
    ):
        assert key in rep
    assert all({"name", "params", "rmse_after_mm"} <= set(e) for e in rep["effects"])
    assert all({"name", "score"} <= set(c) for c in rep["candidates"])
    assert rep["rmse_after_mm"] < 1.3 * rep["noise_floor_mm"] < rep["rmse_declared_mm"]
    md = (out / "report.md").read_text()
    assert "| declared design" in md and "registration" in md
    for png in rep["plots"]:
        assert (out / png).stat().st_size > 20_000
    # the calibrated robot is a design file the design tools take, with the fitted numbers in it
    calibrated = out / "calibrated.design.json"
    robot = tz.Robot.from_json(calibrated)
    phys = rep["parameters"]["physical"]
    np.testing.assert_allclose(np.asarray(robot.lengths), phys["length"], rtol=1e-15)
    np.testing.assert_allclose(np.asarray(robot.backbone_EI), phys["EI"], rtol=1e-15)
    assert (
        main(["sweep", "--design", str(calibrated), "--theta-step", "17", "--out", str(tmp_path / "s.npz"), "--quiet"])
        == 0
    )


def test_a_calibrated_design_file_keeps_every_fitted_routing_and_per_wire_value():
    """FTDCR v4's shipped report: the design file's robot has the calibration's routing exactly (the
    twist between segments, the fitted radii), and its block the per-wire values a segment cannot hold."""
    from tension_zones.calibration._design_file import calibrated_design

    rep = json.loads(tz.example_path("ftdcr_v4/calibration.json").read_text())
    d = calibrated_design(rep["parameters"], (3, 3, 3))
    robot, phys = tz.Robot.from_dict(d), rep["parameters"]["physical"]
    cross = np.asarray(robot.crosses)
    np.testing.assert_allclose(
        np.degrees(robot.route_angles)[cross], np.asarray(phys["route_angles_deg"])[cross], atol=1e-12
    )
    np.testing.assert_allclose(np.asarray(robot.route_radii)[cross], np.asarray(phys["route_radii"])[cross], rtol=1e-15)
    block = tz.Robot.calibrated_block(d)
    assert block["preload_N"] == phys["preload"]
    assert block["wire_play_mm"] == [rep["parameters"]["fitted"]["backlash"][f"play_{k}_mm"] for k in range(1, 10)]
    shipped = json.loads(tz.example_path("ftdcr_v4/calibrated.design.json").read_text())
    assert shipped == calibrated_design(rep["parameters"], (3, 3, 3), "calibration.json")  # it ships regenerated
    d["calibrated"]["wire_play_mm"][0] = -0.1
    with pytest.raises(ValueError, match="wire_play_mm must be at least 0"):
        tz.Robot.from_dict(d)


def test_ftdcr_v6_ships_its_calibration_and_the_robot_of_it():
    """FTDCR v6's shipped report (a CLI run on train.csv alone) and its design file, regenerated from it:
    the effects it found, no play (no backlash identified), the fitted weight in the block."""
    from tension_zones.calibration._design_file import calibrated_design

    rep = json.loads(tz.example_path("ftdcr_v6/calibration.json").read_text())
    assert rep["validate"] is None and rep["data"].endswith("ftdcr_v6/train.csv")
    assert "backlash" not in rep["parameters"]["fitted"]
    shipped = json.loads(tz.example_path("ftdcr_v6/calibrated.design.json").read_text())
    assert shipped == calibrated_design(rep["parameters"], (3, 3, 3), "calibration.json")
    block = tz.Robot.calibrated_block(shipped)
    assert "wire_play_mm" not in block and block["gravity_N_per_mm"][2] < 0
    assert tz.Robot.from_dict(shipped).n_wires == 9


def test_worker_count(monkeypatch):
    """How many worker processes the loop starts (calibration/_fits.py): never where spawn would run a
    plain script's top level again, nor for small problems; the environment variable is checked."""
    import os
    import sys

    from tension_zones.calibration._fits import MAX_WORKERS, MIN_WORK, worker_count

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    cap = max(cores - 1, 1)  # a count asked for is capped at one per spare core
    monkeypatch.setenv("TENSION_ZONES_WORKERS", "2")
    assert worker_count() == min(2, cap) and worker_count(0) == 0 and worker_count(3, work=1) == min(3, cap)
    assert worker_count(1000) == cap and worker_count(1) == 1
    monkeypatch.setenv("TENSION_ZONES_WORKERS", "two")
    with pytest.raises(ValueError, match="TENSION_ZONES_WORKERS must be a whole number"):
        worker_count()
    monkeypatch.delenv("TENSION_ZONES_WORKERS")
    main_module = sys.modules["__main__"]
    monkeypatch.setattr(main_module, "__file__", "/somewhere/script.py", raising=False)
    monkeypatch.setattr(main_module, "__spec__", None, raising=False)
    monkeypatch.setattr(sys, "argv", ["/somewhere/script.py"])
    assert worker_count(None, 10 * MIN_WORK) == 0  # a plain script
    monkeypatch.delattr(main_module, "__file__")  # interactive, a notebook, python -c
    assert worker_count(None, 10 * MIN_WORK) == max(0, min(cores - 1, MAX_WORKERS))
    assert worker_count(None, MIN_WORK - 1) == 0  # too small to win a worker's start back


def test_an_interrupted_report_leaves_nothing_and_the_rerun_works(tmp_path, monkeypatch, capsys):
    """Ctrl-C while the report is written: no plot, no report, no staging folder; the same command again
    writes the report without --force."""
    from tension_zones.calibration import _report

    csv, dj = write_set(tmp_path, "nom", Truth(), 240, seed=2)
    out = tmp_path / "out"
    argv = ["calibrate", str(csv), "--design", str(dj), "--out", str(out), "--quiet"]

    def interrupted(report):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(_report, "markdown", interrupted)
        assert main(argv) == 130
    assert "interrupted" in capsys.readouterr().err
    assert list(out.iterdir()) == []
    assert main(argv) == 0
    assert {"report.json", "report.md"} <= {p.name for p in out.iterdir()}


def test_the_effects_kept_are_records_and_reading_them_as_dicts_is_deprecated():
    """``Result.effects`` holds ``Added`` records (``to_dict``: report.json's form, keys in its order);
    ``effect["name"]``, as when they were dicts, still answers, with a DeprecationWarning."""
    from tension_zones.calibration._rounds import Added

    e = Added("backlash", 0.09, 7.5)
    assert list(e.to_dict()) == ["name", "rmse_after_mm", "score"]
    done = dataclasses.replace(e, params={"play_1_mm": 0.3}, params_std={"play_1_mm": 0.01})
    assert list(done.to_dict()) == ["name", "rmse_after_mm", "score", "params", "params_std"]
    with pytest.warns(DeprecationWarning, match=r"read effect.name, not effect\['name'\]"):
        assert done["name"] == "backlash"
    with pytest.warns(DeprecationWarning), pytest.raises(KeyError):
        e["params"]  # (not there before the final refit, as the dict had no such key)


@pytest.mark.parametrize("err_without, removed", [(1.01, True), (1.2, False)])
def test_the_backward_step_removes_an_earlier_effect_that_only_stood_in(err_without, removed):
    """Once an effect is kept, each earlier one is refitted without it: one whose removal raises the
    held-out sum of squares (in units of the residual's variance) by less than its chi-square quantile
    goes, with its refit's parameters and errors, and the round records it; one that still matters
    stays. (The refits are given: the step's bookkeeping, not a fit.)"""
    from tension_zones.calibration._diagnose import chi2_quantile
    from tension_zones.calibration._loop import _Branch, _Loop
    from tension_zones.calibration._rounds import Added, Refit, Round

    class Refits:  # "refit_held_only": (theta, held-out RMSE, decision error) without each earlier effect
        def map(self, kind, jobs):
            assert kind == "refit_held_only" and [rest for _, rest in jobs] == [["n", "b"]]
            return [(theta * 0.5, err_without, err_without) for theta, _ in jobs]

    sl = {"n": slice(0, 1), "a": slice(1, 3), "b": slice(3, 4)}
    given = {"sl": sl, "run": Refits(), "m": 100, "sigma": np.ones(3), "alpha": 0.01, "say": lambda _: None}
    given["pb"] = type("Pb", (), {"null": np.zeros(4)})()  # (only its null values are read)
    loop = _Loop(**{**{f.name: None for f in dataclasses.fields(_Loop)}, **given})
    st = _Branch(theta=np.ones(4), err=1.5, plain=1.5, active=["n", "a"], effects=[Added("a", 1.5, 5.0)])
    b = Refit("b", 1.0, 1.0, 0.5, 0.1, 0.5, 50.0, 50.0, 6.6, True, False, np.full(4, 2.0), 1.0, 4.0)
    assert loop.keep(st, [b], b, Round(1, 3.0, 1.5, 1.5))
    rise = (err_without**2 - 1.0) * 100  # (the unit: the noise's variance, 1, above 1.0^2 / 3)
    assert (rise < chi2_quantile(0.01, 2)) == removed
    assert st.active == (["n", "b"] if removed else ["n", "a", "b"])
    assert [e.name for e in st.effects] == (["b"] if removed else ["a", "b"])
    assert st.err == (err_without if removed else 1.0)
    np.testing.assert_array_equal(st.theta, [1.0, 0.0, 0.0, 1.0] if removed else np.full(4, 2.0))
    rd = st.rounds[-1]
    assert rd.accepted == "b" and [r.name for r in rd.removed] == (["a"] if removed else [])
    assert st.models[-1][0] == st.active
