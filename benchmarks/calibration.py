"""Calibration speed, end to end, side by side with the code before the one-loop rewrite.

    python benchmarks/calibration.py --baseline DIR [--json out.json] [--no-readme]

``DIR`` is a checkout of the baseline (``git worktree add DIR dce5739``: the last commit with the
separate multi-segment stack). Every case runs ``tension-zones calibrate`` in a fresh process (what a
lab engineer waits for: imports, compilation, fits, report), one case after the other, with
``JAX_LOG_COMPILES=1`` so that the number of XLA compilations is counted from the log. This code runs
each case twice: with an empty compilation cache (a first run), then again with the cache the first run
filled (every later run of the same robot; ``tension_zones/_xla.py``), and once more with that cache and
no worker processes (``--workers 0``: the loop's fits on the one process, ``calibration/_fits.py``). The
compilations counted include the workers' (their log goes to the same stream). The baseline has no
cache. Cases:

* FTDCR v4, ``train.csv`` with ``val.csv`` as the validation file (``--format opencr``);
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


def run(code_root: Path, args: list[str], cache: str | None = None) -> dict:
    env = dict(os.environ, JAX_LOG_COMPILES="1", PYTHONWARNINGS="ignore", TENSION_ZONES_CACHE=cache or "0")
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    t0 = time.perf_counter()
    r = subprocess.run(
        [sys.executable, "-c", _CHILD, str(code_root), *args],
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
        "FTDCR v4 (3 segments, 1620 + 443 samples)": [
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
    p.add_argument("--baseline", help="a checkout of the baseline commit (needed unless --only new)")
    p.add_argument("--json", help="write the numbers to this JSON file")
    p.add_argument("--no-readme", action="store_true", help="do not rewrite benchmarks/README.md")
    p.add_argument("--only", choices=("new", "baseline"), help="run one side only")
    p.add_argument("--keep", help="keep this code's report folders under this folder")
    args = p.parse_args(argv)
    if args.baseline is None and args.only != "new":
        p.error("--baseline DIR is needed unless --only new")
    res = {
        "started": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "load_at_start": load(),
        "rows": [],
        "argv": " ".join(argv if argv is not None else sys.argv[1:]),
    }
    for side, root in (("this code", ROOT), ("baseline", Path(args.baseline or ".").resolve())):
        if args.only and (args.only == "new") != (side == "this code"):
            continue
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(args.keep) if args.keep and side == "this code" else Path(tmp)
            for name, cli in cases(out).items():
                c = f"{tmp}/cache"
                runs = (
                    (("none", None, None),)
                    if side == "baseline"
                    else (("empty", c, "default"), ("filled", c, "default"), ("filled", c, "0"))
                )
                for cache_state, cache, workers in runs:
                    print(f"[{side}, cache {cache_state}, workers {workers}] {name} ...", flush=True)
                    extra = (["--force"] if cache_state == "filled" else []) + (
                        ["--workers", "0"] if workers == "0" else []
                    )
                    r = run(root, cli + extra, cache)
                    r.update(side=side, case=name, cache=cache_state, workers=workers, load=load())
                    print(json.dumps(r), flush=True)
                    res["rows"].append(r)
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))
    md = markdown(res)
    print(md)
    if not args.no_readme:
        from _readme import write_section

        write_section("CALIBRATION", md)


def markdown(res) -> str:
    lines = [
        (
            f"`python benchmarks/calibration.py {res.get('argv', '--baseline DIR')}`, started {res['started']} "
            f"({res['load_at_start']})."
        ),
        "",
        (
            "| case | code | compilation cache | worker processes | seconds (in process) | wall seconds (fresh "
            "process) | XLA compilations |"
        ),
        "|---|---|---|---|---:|---:|---:|",
    ]
    for r in res["rows"]:
        workers = {"default": "default", "0": "none", None: "-"}[r.get("workers")]
        lines.append(
            f"| {r['case']} | {r['side']} | {r.get('cache', 'none')} | {workers} | {r['seconds']:.1f} | "
            f"{r['wall_seconds']:.1f} | {r['compilations']} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
