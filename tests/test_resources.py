"""Resources bounded and visible: memory estimates refused up front with one line, Ctrl-C
within seconds (status 130, nothing that looks finished), explore's folder lock, a coordinator that
does not answer."""

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import tension_zones as tz
from tension_zones import _io, _resources
from tension_zones.cli import main

ROOT = Path(__file__).parents[1]
SPACE = {
    "n_wires": [3],
    "pitch_radius_mm": [1.0, 2.0],
    "sample": {"method": "grid", "points": 2},
    "theta_L_deg": [10, 80, 35],
    "delta_deg": [0, 300, 60],
}
#: Work in many small chunks, long enough to be interrupted midway (16 wires cost far more per pose than 3).
SLOW_SPACE = {
    "n_wires": [16],
    "pitch_radius_mm": [1.0, 2.0],
    "sample": {"method": "grid", "points": 24},
    "theta_L_deg": [0, 84, 2],
    "delta_deg": [0, 360, 1],
    "chunks": {"designs": 2, "poses": 1320},
}
#: A sweep long enough to be interrupted midway (128 wires: the measures cost n^2 per pose).
SWEEP_128 = [
    "sweep",
    "--wires",
    "128",
    "--length",
    "20",
    "--pitch-radius",
    "2",
    "--theta-step",
    "2",
    "--delta-step",
    "2",
]


def _one_line(capsys, rc, code=2):
    err = capsys.readouterr().err
    assert rc == code and err.count("\n") == 1 and err.startswith("tension-zones: error: "), err
    assert "Traceback" not in err
    return err


def test_calibrate_beyond_the_machines_memory_is_refused_up_front(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(_resources, "machine_memory", lambda: int(1.6e9))  # a 1.6 GB machine
    rows = tz.example_path("synthetic/nominal_3w.csv").read_text().splitlines()
    (tmp_path / "cal.csv").write_text("\n".join(rows) + "\n")
    design = str(tz.example_path("synthetic/nominal_3w.design.json"))
    argv = ["calibrate", str(tmp_path / "cal.csv"), "--design", design, "--out", str(tmp_path / "o"), "--workers", "0"]
    err = _one_line(capsys, main(argv))
    assert (
        "calibrating 400 samples x 1 segment(s) needs about 800 MB of memory (estimated), more than 50% of "
        "the 1.6 GB of memory here; pass --subsample 2 (one sample in 2, in acquisition order) or "
        "--no-resource-check to run it anyway"
    ) in err, err
    assert not (tmp_path / "o").exists()
    err = _one_line(capsys, main(argv + ["--subsample", "0"]))
    assert "--subsample must be 1 or more, got 0" in err
    # --force replaces an earlier report and nothing else: the memory check stands
    assert "needs about 800 MB of memory" in _one_line(capsys, main(argv + ["--force"]))


def test_no_resource_check_runs_a_calibration_past_the_memory_check(tmp_path, capsys, monkeypatch):
    """The calibration is reached (here a stand-in that stops it), the estimate said first."""
    import tension_zones.calibration

    def reached(*args, log=None, **kw):
        log("the loop starts")
        raise ValueError("the calibration was reached")

    monkeypatch.setattr(_resources, "machine_memory", lambda: int(1.6e9))
    monkeypatch.setattr(tension_zones.calibration, "calibrate", reached)
    design = str(tz.example_path("synthetic/nominal_3w.design.json"))
    data = str(tz.example_path("synthetic/nominal_3w.csv"))
    argv = ["calibrate", data, "--design", design, "--out", str(tmp_path / "o"), "--workers", "0"]
    rc = main(argv + ["--no-resource-check"])
    err = capsys.readouterr().err
    assert rc == 2 and err.splitlines() == [
        "calibrating 400 samples x 1 segment(s): about 800 MB of memory (estimated)",
        "the loop starts",
        "tension-zones: error: the calibration was reached",
    ], err


def test_workers_beyond_the_cores_are_capped_with_a_note(tmp_path, capsys, monkeypatch):
    from tension_zones.calibration import _fits

    for module in (_resources, _fits):
        monkeypatch.setattr(module, "cores", lambda: 2)
    monkeypatch.setattr(_resources, "machine_memory", lambda: int(1e8))  # refused after the note: no fit
    design = str(tz.example_path("synthetic/nominal_3w.design.json"))
    data = str(tz.example_path("synthetic/nominal_3w.csv"))
    rc = main(["calibrate", data, "--design", design, "--out", str(tmp_path / "o"), "--workers", "1000"])
    note, error = capsys.readouterr().err.splitlines()
    assert rc == 2 and note == (
        "tension-zones: note: --workers 1000 capped at 1 (one per core beyond the first, at least one; 2 core(s) here)"
    )
    assert error.startswith("tension-zones: error: calibrating 400 samples x 1 segment(s) with 1 worker process(es)")


def test_a_chunk_beyond_the_machines_memory_is_refused_and_the_work_said(tmp_path, capsys):
    big = tmp_path / "big.json"
    big.write_text(json.dumps({**SPACE, "chunks": {"poses": 10**9}}))
    err = _one_line(capsys, main(["explore", "--space", str(big), "--out", str(tmp_path / "o")]))
    assert "a chunk of 128 designs x 1,000,000,000 poses of 3 wires needs about 465 GB of memory (estimated)" in err
    assert 'lower the space\'s "chunks" ("poses": the poses per step), or pass --no-resource-check' in err
    assert not (tmp_path / "o").exists()
    line = tz.design._explore.plan(tz.parse_space(SPACE))
    assert line.startswith("exploring 2 designs x 18 poses = 36 design-poses in 1 chunk(s) (about "), line


#: A day and a half of estimated computing (16 wires: four times the cost of a pose at 4).
DAY_SPACE = {
    "n_wires": [16],
    "sample": {"method": "halton", "designs": 1_000_000},
    "theta_L_deg": [0, 85, 0.5],
    "delta_deg": [0, 360, 1],
}


def test_the_work_is_estimated_up_front_and_refused_past_the_caps():
    """The line says the estimated computing; past ``MAX_CHUNKS`` or ``MAX_WORK_S`` ``plan`` refuses
    (rows in test_bad_inputs) unless the resource checks are off."""
    from tension_zones.design import _explore

    line = _explore.plan(tz.parse_space(DAY_SPACE), resource_check=False)
    assert line == (
        "exploring 1,000,000 designs x 61,731 poses = 6.17e+10 design-poses in 7,813 chunk(s) (about 5.64 MB of "
        "memory per chunk; about 34 h of computing, estimated)"
    )
    with pytest.raises(ValueError, match="would take about 34 h of computing"):
        _explore.plan(tz.parse_space(DAY_SPACE))
    many = tz.parse_space({**SPACE, "sample": {"method": "halton", "designs": 200_000}, "chunks": {"designs": 1}})
    assert "in 200,000 chunk(s)" in _explore.plan(many, resource_check=False)
    with pytest.raises(ValueError, match="more than 100,000 chunks"):
        _explore.plan(many)
    assert [_explore.about(s) for s in (0.25, 42, 95, 5000, 90_000, 2e6)] == [
        "0.25 s",
        "42 s",
        "1.6 min",
        "83 min",
        "25 h",
        "23 days",
    ]


def test_no_resource_check_starts_an_exploration_past_the_caps(tmp_path, capsys, monkeypatch):
    """The work line first, then the exploration (here a stand-in that stops it) is reached."""
    from tension_zones.design import _explore

    def reached(space, out, resource_check=True, **kw):
        raise ValueError(f"explore was reached (resource_check={resource_check})")

    monkeypatch.setattr(_explore, "explore", reached)
    space = tmp_path / "day.json"
    space.write_text(json.dumps(DAY_SPACE))
    argv = ["explore", "--space", str(space), "--out", str(tmp_path / "o")]
    assert "would take about 34 h of computing" in _one_line(capsys, main(argv))
    assert main(argv + ["--no-resource-check"]) == 2
    out, err = capsys.readouterr()
    assert out.startswith("exploring 1,000,000 designs x 61,731 poses") and "about 34 h of computing" in out, out
    assert err == "tension-zones: error: explore was reached (resource_check=False)\n"


def test_explore_locks_its_folder_and_a_stale_lock_does_not_block(tmp_path, capsys):
    space = tmp_path / "space.json"
    space.write_text(json.dumps(SPACE))
    out = tmp_path / "out"
    out.mkdir()
    (out / _io.LOCK_NAME).write_text(f"1 {os.uname().nodename}\n")  # pid 1: alive, not ours
    err = _one_line(capsys, main(["explore", "--space", str(space), "--out", str(out), "--quiet"]))
    assert f"{str(out)!r} is in use by another explore (process 1 on {os.uname().nodename})" in err
    # a lock left by a process that was killed (no such pid) is taken over; the run releases it
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (out / _io.LOCK_NAME).write_text(f"{dead.pid} {os.uname().nodename}\n")
    assert main(["explore", "--space", str(space), "--out", str(out), "--quiet"]) == 0
    assert (out / "table.npz").exists() and not (out / _io.LOCK_NAME).exists()


def _dead_pid() -> int:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    return dead.pid


def test_temporaries_of_a_killed_process_go_with_the_next_write_and_others_stay(tmp_path):
    """A killed writer's hidden file and stage (its process gone, this host) are removed by the next
    write into that folder; a live process's, another host's and unrelated hidden files stay."""
    host = os.uname().nodename
    left = [tmp_path / f".r.{_dead_pid()}-{host}-x1.json", tmp_path / f"{_io.STAGE_PREFIX}{_dead_pid()}-{host}-x2"]
    kept = [
        tmp_path / f".r.1-{host}-x3.json",  # pid 1: alive
        tmp_path / f".r.{_dead_pid()}-elsewhere-x4.json",  # another host's
        tmp_path / f".q.{_dead_pid()}-{host}-x5.json",  # another file's
        tmp_path / ".hidden",
    ]
    left[1].mkdir()
    for p in [left[0], *kept]:
        p.write_text("{}")
    _io.write_json(tmp_path / "r.json", {"a": 1})
    assert not left[0].exists() and left[1].exists()  # a file's write clears its own temporaries only
    with _io.staged_folder(tmp_path) as stage:
        (stage / "s.txt").write_text("x")
    assert not left[1].exists() and all(p.exists() for p in kept)
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == ["r.json", "s.txt"]


def test_a_command_ended_without_unwinding_removes_what_it_was_writing(tmp_path):
    """What the Ctrl-C watchdog calls before it ends the process inside a block that never ends: the
    stage and the file being written go; nothing appears."""
    blocks = [_io.staged_folder(tmp_path / "o"), _io.atomic_path(tmp_path / "f.npz")]
    stage, tmp = (b.__enter__() for b in blocks)
    tmp.write_bytes(b"half")
    (stage / "report.json").write_text("{")
    _io.remove_temporaries()
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["o"]


def test_a_coordinator_that_does_not_answer_is_one_line(tmp_path, capsys):
    space = tmp_path / "space.json"
    space.write_text(json.dumps(SPACE))
    t0 = time.monotonic()
    rc = main(
        [
            "explore",
            "--space",
            str(space),
            "--out",
            str(tmp_path / "o"),
            "--coordinator",
            "127.0.0.1:1",
            "--num-processes",
            "2",
            "--process-id",
            "1",
            "--coordinator-timeout",
            "0.5",
        ]
    )
    err = _one_line(capsys, rc)
    assert time.monotonic() - t0 < 5
    assert (
        "--coordinator 127.0.0.1:1 did not answer within 0.5 s (Connection refused); start process 0 first, "
        "check the address, or raise --coordinator-timeout"
    ) in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_process_0_whose_workers_never_join_gives_up_in_one_line(tmp_path):
    """Process 0 of two, the other never started: one line and status 2 at --coordinator-timeout
    (before JAX's own timeout, past which it would abort from C++), nothing written."""
    import socket

    from tension_zones.cli import JOIN_MARGIN_S

    space = tmp_path / "space.json"
    space.write_text(json.dumps(SPACE))
    with socket.socket() as s:  # a free port
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    argv = ["explore", "--space", str(space), "--out", str(tmp_path / "o"), "--coordinator", f"127.0.0.1:{port}"]
    argv += ["--num-processes", "2", "--process-id", "0", "--coordinator-timeout", "3"]
    t0 = time.monotonic()
    cmd = [sys.executable, "-m", "tension_zones.cli", *argv]
    r = subprocess.run(cmd, env=_cli_env(), capture_output=True, text=True, timeout=120, check=False)
    assert time.monotonic() - t0 < 3 + JOIN_MARGIN_S
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr == (
        f"tension-zones: error: not every one of the 2 processes (--num-processes) joined --coordinator "
        f"127.0.0.1:{port} within 3 s (this is process 0); start every --process-id 0..1 with the same "
        "--coordinator and --num-processes, or raise --coordinator-timeout\n"
    )
    assert not (tmp_path / "o").exists()


#: Ctrl-C stops every command within this many seconds.
STOP_S = 5


def _cli_env():
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


#: ``tension-zones`` with SIGINT raising KeyboardInterrupt, as in a terminal: a runner that ignores
#: SIGINT (a background job of a non-interactive shell, some test workers) passes the ignoring on to
#: its children, and Python then installs no KeyboardInterrupt handler.
CLI_WITH_CTRL_C = (
    "import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "from tension_zones.cli import run; run(sys.argv[1:])"
)


def _interrupt(argv, started, log: Path, settle: float = 0.0) -> str:
    """Run ``tension-zones argv`` in a process of its own, send it Ctrl-C (SIGINT) once
    ``started(stderr so far)`` holds (and ``settle`` seconds more), and check how it ends: status 130
    within ``STOP_S`` of the signal, one line ``tension-zones: interrupted`` and no traceback on
    stderr (progress output above it). Returns stderr. (stderr goes to the file ``log``, read as it
    grows.)"""
    with open(log, "w") as sink:
        p = subprocess.Popen(
            [sys.executable, "-c", CLI_WITH_CTRL_C, *argv], env=_cli_env(), stdout=subprocess.DEVNULL, stderr=sink
        )
        try:
            deadline = time.monotonic() + 180
            while not started(log.read_text()):
                if p.poll() is not None or time.monotonic() > deadline:
                    pytest.fail(f"ended or stalled before its work started (status {p.poll()}): {log.read_text()}")
                time.sleep(0.02)
            time.sleep(settle)
            p.send_signal(signal.SIGINT)
            t0 = time.monotonic()
            p.wait(timeout=30)
            seconds = time.monotonic() - t0
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
    err = log.read_text()
    assert p.returncode == 130 and seconds < STOP_S, (p.returncode, seconds, err)
    assert err.endswith("tension-zones: interrupted\n") and err.count("tension-zones:") == 1, err
    assert "Traceback" not in err, err
    return err


@pytest.mark.slow
def test_ctrl_c_stops_a_long_optimize_within_seconds(tmp_path):
    """A compiled loop of 10^8 steps does not return to Python: the watchdog ends it, status 130, one
    line, no result folder."""
    scenario = tmp_path / "long.json"
    scenario.write_text(
        json.dumps(
            {
                "n_wires": [3],
                "theta_L_deg": [30, 80, 50],
                "delta_deg": [0, 350, 50],
                "optimizer": {"starts": 1, "steps": 10**8},
            }
        )
    )
    argv = ["optimize", "--scenario", str(scenario), "--out", str(tmp_path / "o")]
    # the progress bar says the command runs; a second more takes it into the compile or the compiled loop
    _interrupt(argv, lambda err: "wire counts" in err, tmp_path / "stderr.txt", settle=1.0)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_ctrl_c_stops_a_sweep_and_the_rerun_writes_it(tmp_path, capsys):
    """Interrupted once its progress bar has moved: no .npz (nor a hidden one); the same command then
    writes it."""
    out = tmp_path / "s.npz"
    argv = SWEEP_128 + ["--out", str(out)]
    _interrupt(argv, lambda err: re.search(r"sweep: +[1-9]\d*%", err) is not None, tmp_path / "stderr.txt")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stderr.txt"]
    assert main(argv) == 0
    with np.load(out) as f:
        assert f["dp_max_reduced"].shape == (43, 181)


@pytest.mark.slow
def test_ctrl_c_stops_an_explore_and_the_rerun_resumes_it(tmp_path, capsys):
    """Interrupted once a chunk is saved: the folder holds the manifest and the chunks done, no table
    and no front; the same command resumes from those chunks and writes them."""
    space = tmp_path / "space.json"
    space.write_text(json.dumps(SLOW_SPACE))
    out = tmp_path / "o"

    def chunks_done(_err):
        try:
            return sum(map(len, json.loads((out / "manifest.json").read_text())["done"].values()))
        except (OSError, ValueError):
            return 0

    argv = ["explore", "--space", str(space), "--out", str(out)]
    _interrupt(argv, chunks_done, tmp_path / "stderr.txt")
    done = chunks_done("")
    assert 1 <= done < 12
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["chunks", "manifest.json"]
    assert json.loads((out / "manifest.json").read_text())["complete"] is False
    capsys.readouterr()
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert f"resuming the exploration in {str(out)!r}: " in said, said
    assert int(said.split(": ")[1].split(" of ")[0]) >= done, said
    assert {"table.npz", "table.csv", "front.csv"} <= {p.name for p in out.iterdir()}
    with np.load(out / "table.npz") as table:
        assert table["design"].size == 24 and np.all(np.isfinite(table["dp_max_reduced_worst"]))


@pytest.mark.slow
def test_ctrl_c_stops_a_calibration_and_the_rerun_reports(tmp_path, capsys):
    """Interrupted after the nominal fit: no report, no plot; the same command then writes the report
    (the folder holds nothing a rerun would refuse)."""
    out = tmp_path / "o"
    argv = [
        "calibrate",
        str(tz.example_path("synthetic/unknown_a_3w.csv")),
        "--design",
        str(tz.example_path("synthetic/unknown_a_3w.design.json")),
        "--out",
        str(out),
    ]
    _interrupt(argv, lambda err: "noise floor" in err, tmp_path / "stderr.txt")
    assert not out.exists() or not [p for p in out.iterdir() if not p.name.startswith(".")]
    assert main(argv) == 0
    report = json.loads((out / "report.json").read_text())
    assert [e["name"] for e in report["effects"]] == ["backlash"]
    assert not [p for p in out.iterdir() if p.name.startswith(".partial-")]
