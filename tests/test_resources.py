"""Resources bounded and visible: memory estimates refused up front with one line, Ctrl-C
within seconds (status 130, nothing that looks finished), explore's folder lock, a coordinator that
does not answer."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

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
        "the 1.6 GB of memory here; pass --subsample 2 (one sample in 2, in acquisition order) or --force to run "
        "it anyway"
    ) in err, err
    assert not (tmp_path / "o").exists()
    err = _one_line(capsys, main(argv + ["--subsample", "0"]))
    assert "--subsample must be 1 or more, got 0" in err


def test_a_chunk_beyond_the_machines_memory_is_refused_and_the_work_said(tmp_path, capsys):
    big = tmp_path / "big.json"
    big.write_text(json.dumps({**SPACE, "chunks": {"poses": 10**9}}))
    err = _one_line(capsys, main(["explore", "--space", str(big), "--out", str(tmp_path / "o")]))
    assert "a chunk of 128 designs x 1,000,000,000 poses of 3 wires needs about 465 GB of memory (estimated)" in err
    assert 'lower the space\'s "chunks" ("poses": the poses per step)' in err
    assert not (tmp_path / "o").exists()
    line = tz.design._explore.plan(tz.parse_space(SPACE))
    assert line.startswith("exploring 2 designs x 18 poses = 36 design-poses in 1 chunk(s) (about "), line


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
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    p = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tension_zones.cli",
            "optimize",
            "--scenario",
            str(scenario),
            "--out",
            str(tmp_path / "o"),
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    seen = ""
    while "wire counts" not in seen:  # the progress bar: the command is running
        seen += p.stderr.read(1) or pytest.fail(f"ended before its progress bar: {seen}")
    time.sleep(1)  # into the compile or the compiled loop
    p.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    _, err = p.communicate(timeout=30)
    assert time.monotonic() - t0 < 5
    assert p.returncode == 130 and err.endswith("tension-zones: interrupted\n"), err
    assert "Traceback" not in err and err.count("tension-zones:") == 1, err
    assert not (tmp_path / "o").exists()
