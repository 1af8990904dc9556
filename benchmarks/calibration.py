"""Calibration speed, end to end, in fresh processes.

    python benchmarks/calibration.py [--json out.json] [--no-readme] [--keep DIR]

Every case runs ``tension-zones calibrate`` in a fresh process (what a lab engineer waits for: imports,
compilation, fits, report), one case after the other, with ``JAX_LOG_COMPILES=1`` so that the number of
XLA compilations is counted from the log (a worker's included: its log goes to the same stream). Each
case runs with an empty compilation cache (a first run), then again with the cache the first run filled
(every later run of the same robot; ``tension_zones/_xla.py``), and once more with that cache and no
worker processes (``--workers 0``: the loop's fits on the one process, ``calibration/_fits.py``).
Cases:

* FTDCR v4, ``train.csv`` with ``val.csv`` as the validation file (``--format opencr``), and FTDCR v6's
  ``train.csv`` (its validation file is held back); target for both real robots: a first run (empty
  cache, default workers) within ``TARGET_S``;
* a 500-sample single-segment set (the shipped ``synthetic/unknown_a_3w``).

The results go into ``benchmarks/README.md`` between the ``CALIBRATION`` markers.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
EX = ROOT / "tension_zones" / "examples"
#: a real robot's first run, with an empty cache (issue "Calibrate any real robot")
TARGET_S = 120.0
V4 = "FTDCR v4 (3 segments, 1620 + 443 samples)"
V6 = "FTDCR v6 (3 segments, 1019 samples)"

_CHILD = """
import sys, time
sys.path.insert(0, sys.argv[1])
import tension_zones
assert tension_zones.__file__.startswith(sys.argv[1]), tension_zones.__file__
from tension_zones.cli import main
t0 = time.perf_counter()
rc = main(sys.argv[2:])
print("SECONDS", time.perf_counter() - t0, "RC", rc, flush=True)
"""


def run(args: list[str], cache: str | None = None) -> dict:
    env = dict(os.environ, JAX_LOG_COMPILES="1", PYTHONWARNINGS="ignore", TENSION_ZONES_CACHE=cache or "0")
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    t0 = time.perf_counter()
    r = subprocess.run(
        [sys.executable, "-c", _CHILD, str(ROOT), *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=7200,
        check=False,
    )
    wall = time.perf_counter() - t0
    m = re.search(r"SECONDS ([\d.]+) RC (\d+)", r.stdout)
    if not m or m.group(2) != "0":
        raise RuntimeError(f"{args[:2]} failed:\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}")
    compiles = len(re.findall(r"Compiling \S+", r.stderr))
    return {
        "seconds": float(m.group(1)),
        "wall_seconds": wall,
        "compilations": compiles,
        "summary": r.stdout.strip().splitlines()[-2] if len(r.stdout.strip().splitlines()) > 1 else "",
    }


def cases(out: Path):
    ftdcr = EX / "ftdcr_v4"
    return {
        V4: [
            "calibrate",
            str(ftdcr / "train.csv"),
            "--format",
            "opencr",
            "--design",
            str(ftdcr / "design.json"),
            "--validate",
            str(ftdcr / "val.csv"),
            "--out",
            str(out / "ftdcr"),
            "--quiet",
        ],
        V6: [
            "calibrate",
            str(EX / "ftdcr_v6" / "train.csv"),
            "--format",
            "opencr",
            "--design",
            str(EX / "ftdcr_v6" / "design.json"),
            "--out",
            str(out / "ftdcr_v6"),
            "--quiet",
        ],
        "unknown_a_3w (1 segment, 500 samples)": [
            "calibrate",
            str(EX / "synthetic" / "unknown_a_3w.csv"),
            "--design",
            str(EX / "synthetic" / "unknown_a_3w.design.json"),
            "--out",
            str(out / "single"),
            "--quiet",
        ],
    }


def load() -> str:
    return os.popen("uptime").read().strip()


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", help="write the numbers to this JSON file")
    p.add_argument("--no-readme", action="store_true", help="do not rewrite benchmarks/README.md")
    p.add_argument("--keep", help="keep the report folders under this folder")
    args = p.parse_args(argv)
    res = {
        "started": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "load_at_start": load(),
        "rows": [],
        "argv": " ".join(argv if argv is not None else sys.argv[1:]),
    }
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.keep) if args.keep else Path(tmp)
        for k, (name, cli) in enumerate(cases(out).items()):
            c = f"{tmp}/cache-{k}"  # each case its own cache, empty at first
            for cache_state, workers in (("empty", "default"), ("filled", "default"), ("filled", "0")):
                print(f"[cache {cache_state}, workers {workers}] {name} ...", flush=True)
                extra = (["--force"] if cache_state == "filled" else []) + (
                    ["--workers", "0"] if workers == "0" else []
                )
                r = run(cli + extra, c)
                r.update(case=name, cache=cache_state, workers=workers, load=load())
                print(json.dumps(r), flush=True)
                res["rows"].append(r)
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))
    md = markdown(res)
    print(md)
    if not args.no_readme:
        from _readme import write_section

        write_section("CALIBRATION", md)


def _target(r) -> str:
    if r["case"] not in (V4, V6) or r["cache"] != "empty" or r["workers"] != "default":
        return ""
    return f"<= {TARGET_S:.0f} s: " + ("met" if r["wall_seconds"] <= TARGET_S else "MISSED")


def markdown(res) -> str:
    cmd = f"python benchmarks/calibration.py {res['argv']}".strip()
    lines = [
        f"`{cmd}`, started {res['started']} ({res['load_at_start']}).",
        "",
        (
            "| case | compilation cache | worker processes | seconds (in process) | wall seconds (fresh process) "
            "| XLA compilations | target |"
        ),
        "|---|---|---|---:|---:|---:|---|",
    ]
    for r in res["rows"]:
        workers = {"default": "default", "0": "none"}[r["workers"]]
        lines.append(
            f"| {r['case']} | {r['cache']} | {workers} | {r['seconds']:.1f} | {r['wall_seconds']:.1f} | "
            f"{r['compilations']} | {_target(r)} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
