"""The command line: outputs, and one-line errors that lose nothing."""

import subprocess
import sys

import pytest

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


def test_console_script_runs(tmp_path):
    r = subprocess.run([sys.executable, "-m", "tension_zones.cli", "maps", "--wires", "5",
                        "--out", str(tmp_path / "m5.png"), "--quiet"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "wires" in r.stdout and r.stderr == ""
