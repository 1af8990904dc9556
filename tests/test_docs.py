"""The documentation site builds (``mkdocs build --strict``): a docstring reference, a page or a link
that breaks fails here, and the API pages hold the public names."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_docs_build_strict(tmp_path):
    site = tmp_path / "site"
    r = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "-f", str(ROOT / "docs" / "mkdocs.yml"), "--strict", "-d", str(site)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
        check=False,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    pages = {
        p: (site / p / "index.html").read_text(encoding="utf-8")
        for p in (
            "api/model",
            "api/analysis",
            "api/design",
            "api/calibration",
            "api/paper",
            "formats",
            "notes/model",
            "notes/calibration",
            "notes/design",
        )
    }
    for page, names in {
        "api/model": ("Robot", "Design", "tip_pose", "equilibrium", "reduced_J_xq"),
        "api/analysis": ("sweep_grid", "pose_measures", "sweep_designs"),
        "api/design": ("optimize", "explore", "pareto_front"),
        "api/calibration": ("calibrate", "read_opencr", "Dataset", "backlash"),
        "api/paper": ("reproduce",),
    }.items():
        for name in names:
            assert 'id="tension_zones.' in pages[page] and name in pages[page], (page, name)
