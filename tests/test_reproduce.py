"""`tension-zones reproduce` end to end, and the README's two set-up commands."""

import json
import pathlib
import re
import subprocess
import sys

import pytest

from tension_zones.cli import main

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_readme_has_exactly_the_two_setup_commands():
    text = (ROOT / "README.md").read_text()
    assert text.count("<!-- main-command -->") == 1 and text.count("<!-- test-command -->") == 1
    lines = text.splitlines()
    main_cmd = lines[lines.index("<!-- main-command -->") + 2]
    test_cmd = lines[lines.index("<!-- test-command -->") + 2]
    assert "pip install" in main_cmd and "tension-zones reproduce" in main_cmd
    assert "pip install" in test_cmd and "pytest" in test_cmd
    assert "test-command" in (ROOT / ".ci" / "run").read_text()


def test_readme_is_a_short_front_door():
    text = (ROOT / "README.md").read_text()
    assert len(text.encode()) <= 10 * 1024
    assert re.search(r"issue \d", text, re.IGNORECASE) is None and "../shared" not in text


@pytest.mark.slow
def test_readme_example_runs_from_an_empty_folder(tmp_path):
    """The README's ten lines, run where there is nothing but the installed package."""
    text = (ROOT / "README.md").read_text()
    code = text.split("## Ten lines of Python", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    assert 8 <= len(code.strip().splitlines()) <= 12
    r = subprocess.run(
        [sys.executable, "-c", code + "\nassert res.effects[0].name == 'backlash'"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert "taut" in r.stdout and "backlash" in r.stdout


@pytest.mark.slow
def test_reproduce_writes_figures_and_summary(tmp_path):
    assert main(["reproduce", "--out", str(tmp_path), "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["tension_maps"]["one_taut_wire_fraction"]["3"] > 0.45
    assert summary["tension_maps"]["one_taut_wire_fraction"]["4"] < 0.02
    assert (tmp_path / "fig5_tension_map_3w.png").stat().st_size > 10_000
    # Sec. 6.2: identified segment, Tables 1-2 within 10 % on average, three-wire ratio >= 2.5
    from tension_zones.paper._identify import PAPER_TABLE

    comp = summary["compliance"]
    ident = comp["identified"]
    assert 10 <= ident["length_mm"] <= 40 and 1 <= ident["pitch_radius_mm"] <= 3
    assert 10 <= ident["backbone_EI_Nmm2"] <= 5000
    errs = [
        abs(comp["table"][str(n)][str(k)][i] / PAPER_TABLE[n][k][i] - 1)
        for n in (3, 4)
        for k in (55, 75, 105)
        for i in (0, 2)
    ]
    assert len(errs) == 12 and sum(errs) / 12 <= 0.10
    assert comp["reduced_over_traditional_position_mean"]["3"] >= 2.5
    assert (tmp_path / "fig13_compliance.png").stat().st_size > 10_000
