"""Speed and scale, measured side by side in one run.

    python benchmarks/run.py [--quick] [--json OUT.json] [--no-readme]

Every number is the median of at least 5 timed runs after a warm-up, float64, on this machine's CPU;
compile time (first call minus the median) is reported separately. The paths compared are timed
interleaved (one run of each per repeat) and speed-ups are medians of those paired ratios: this
machine's speed drifts by up to ~2x from minute to minute. Results are written into the
table of ``benchmarks/README.md`` (between the RESULTS markers) unless ``--no-readme``.
Targets are reported, never asserted.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import numpy_baselines as nb

import tension_zones as tz

REPEATS = 5


def _seconds(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def grid(theta_step, delta_step):
    th = np.radians(np.arange(0.0, 85.0 + 1e-9, theta_step))
    de = np.radians(np.arange(0.0, 360.0 + 1e-9, delta_step))
    return th, de


# ------------------------------------------------------------------------------------------------
def bench_kinematics(quick):
    """KCI, sigma_min, dp_max, dw_max (full and reduced) for n = 3, 4, 8: loop, NumPy, JAX."""
    from tension_zones.analysis._metrics import pose_metrics
    from tension_zones.analysis._sweep import sweep_grid

    rows = []
    th_small, de_small = grid(5.0, 2.5)  # the paper's grid: 2610 poses
    th_big, de_big = grid(0.5, 0.25) if not quick else grid(1.0, 1.0)
    for n in (3, 4, 8):
        d = tz.Design(n, 20.0, 2.0)
        alpha = np.asarray(d.wire_angles)
        n_big = th_big.size * de_big.size
        n_loop = th_small[:: (6 if n == 8 else 1)].size * de_small.size
        # the per-pose loop is slow (3^n columns): timed on (a slice of) the paper grid
        loop = lambda alpha=alpha, n=n: nb.measures_loop(
            20.0, 2.0, alpha, th_small[:: (6 if n == 8 else 1)], de_small, 0.4
        )
        vec = lambda alpha=alpha: nb.measures_vectorised(20.0, 2.0, alpha, th_big, de_big, 0.4)

        def jax_run(design=d):
            return sweep_grid(pose_metrics, design, th_big, de_big, 0.4, quiet=True)

        first = _seconds(jax_run)
        loop(), vec()  # warm-up
        # interleaved, as for the compliance sweep: speed-ups are medians of back-to-back ratios
        t_l, t_n, t_j = [], [], []
        for _ in range(3 if quick else REPEATS):
            t_l.append(_seconds(loop))
            t_n.append(_seconds(vec))
            t_j.append(_seconds(jax_run))
        t_jax = statistics.median(t_j)
        # new values of the same shapes: no recompile (second design, timed like the median)
        t_new_values = _seconds(lambda d=d: jax_run(d.replace(pitch_radius=2.5, length=25.0)))
        rows.append(
            {
                "n_wires": n,
                "poses": n_big,
                "loop_poses_per_s": n_loop / statistics.median(t_l),
                "numpy_poses_per_s": n_big / statistics.median(t_n),
                "jax_poses_per_s": n_big / t_jax,
                "jax_compile_s": max(first - t_jax, 0.0),
                "jax_new_values_s": t_new_values,
                "jax_median_s": t_jax,
                "speedup_vs_loop": statistics.median(n_big * a / (n_loop * b) for a, b in zip(t_l, t_j)),
                "speedup_vs_numpy": statistics.median(a / b for a, b in zip(t_n, t_j)),
            }
        )
    return rows


def bench_compliance(quick):
    """The compliance sweep on the paper's Sec. 6.2 grid: per pose (SLSQP tensions, NumPy stiffness
    and deflection) vs batched JAX; the two must agree."""
    from tension_zones.model._statics import compliance_grid

    th = np.radians(np.linspace(89.0, 45.0, 10))
    de = np.radians(np.arange(0.0, 360.0 + 1e-9, 15.0))
    w = np.array([5.0, 0, 0, 0, 0, 0])
    rows = []
    for n in (3, 4):
        d = tz.Design(n, 20.0, 2.0)
        alpha = np.asarray(d.wire_angles)
        loop = lambda stiffness=True, d=d, alpha=alpha: nb.compliance_scipy_loop(
            20.0, 2.0, alpha, float(d.backbone_EI), float(d.wire_stiffness), th, de, w, stiffness=stiffness
        )
        ref, ours = loop(), compliance_grid(d, w, np.degrees(th), np.degrees(de))  # also warm-up
        agree = max(
            float(np.nanmax(np.abs(ours[k] - ref[k]) / np.abs(ref[k]))) for k in ref if k.startswith("deflection")
        )
        # the batched path on a grid 100x larger, so the timer sees real work
        th_b = np.radians(np.linspace(89.0, 45.0, 100))
        de_b = np.radians(np.arange(0.0, 360.0, 0.15))
        jax_run = lambda d=d, th_b=th_b, de_b=de_b: compliance_grid(d, w, np.degrees(th_b), np.degrees(de_b))
        t0 = time.perf_counter()
        jax_run()
        first = time.perf_counter() - t0
        # Interleaved: this machine's speed drifts by up to ~2x between minutes, so each repeat times
        # the three paths back to back and the speed-ups are medians of those paired ratios. The
        # loops are timed after a warm-up call (a single cold call also timed the ~0.5 s import of
        # scipy.optimize, which once made the loop look 4x slower than it is).
        t_s, t_o, t_j = [], [], []
        for _ in range(3 if quick else REPEATS):
            t_s.append(_seconds(loop))
            t_o.append(_seconds(lambda loop=loop: loop(stiffness=False)))
            t_j.append(_seconds(jax_run))
        n_loop, n_jax = th.size * de.size, th_b.size * de_b.size
        rows.append(
            {
                "n_wires": n,
                "scipy_poses_per_s": n_loop / statistics.median(t_s),
                "slsqp_only_poses_per_s": n_loop / statistics.median(t_o),
                "jax_poses_per_s": n_jax / statistics.median(t_j),
                "jax_compile_s": max(first - statistics.median(t_j), 0.0),
                "speedup": statistics.median(n_jax * a / (n_loop * b) for a, b in zip(t_s, t_j)),
                "speedup_vs_slsqp_only": statistics.median(n_jax * a / (n_loop * b) for a, b in zip(t_o, t_j)),
                "max_rel_difference": agree,
            }
        )
    return rows


_SCALING_CHILD = textwrap.dedent("""
    import json, sys, time
    import numpy as np
    import tension_zones as tz
    from tension_zones.analysis._metrics import pose_metrics
    from tension_zones.analysis._sweep import sweep_grid
    n_poses, n_wires = int(sys.argv[1]), int(sys.argv[2])
    n_delta = 1441
    n_theta = max(1, round(n_poses / n_delta))
    th = np.radians(np.linspace(0.0, 85.0, n_theta)); de = np.radians(np.linspace(0, 360, n_delta))
    d = tz.Design(n_wires, 20.0, 2.0)
    t0 = time.perf_counter()
    sweep_grid(pose_metrics, d, th[:1], de, 0.4, quiet=True)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = sweep_grid(pose_metrics, d, th, de, 0.4, quiet=True)  # all 17 arrays kept
    t = time.perf_counter() - t0
    import jax
    # VmHWM: this process's own peak (ru_maxrss would carry the parent's peak across exec)
    hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
    print(json.dumps({"poses": n_theta * n_delta, "seconds": t, "first_call_s": t_first,
                      "devices": jax.device_count(), "arrays": len(out),
                      "peak_rss_mb": int(hwm) / 1024}))
""")


def _child(args, env_extra=None):
    env = dict(os.environ)
    env.update(env_extra or {})
    r = subprocess.run(
        [sys.executable, "-c", _SCALING_CHILD, *map(str, args)],
        env=env,
        capture_output=True,
        text=True,
        timeout=3600,
        check=False,
    )
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-2000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def bench_scaling(quick):
    sizes = [10**3, 10**4, 10**5, 10**6] + ([] if quick else [10**7])
    rows = [_child([n, 4]) for n in sizes]
    big = sizes[-1]
    sharded = _child([big, 4], {"XLA_FLAGS": "--xla_force_host_platform_device_count=4"})
    return {"rows": rows, "sharded_4_host_devices": sharded}


def plot_scaling(scaling, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = scaling["rows"]
    n = [r["poses"] for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].loglog(n, [r["seconds"] for r in rows], "o-")
    ax[0].set_xlabel("poses")
    ax[0].set_ylabel("time (s)")
    ax[0].set_title("Sweep time (4 wires, all measures)")
    ax[0].grid(True, which="both", alpha=0.3)
    ax[1].semilogx(n, [r["peak_rss_mb"] for r in rows], "o-")
    ax[1].axhline(2048, color="r", ls="--", label="2 GB target")
    ax[1].set_xlabel("poses")
    ax[1].set_ylabel("peak resident memory (MB)")
    ax[1].set_title("Peak memory (whole process)")
    ax[1].legend()
    ax[1].grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ------------------------------------------------------------------------------------------------
def machine():
    import jax

    return {
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "numpy": np.__version__,
        "load_average_1min": os.getloadavg()[0],
    }


def machine_line(res) -> str:
    m = res["machine"]
    return (
        f"Machine: {m['cores']} cores ({m['cpu']}), Python {m['python']}, jax {m['jax']}, "
        f"numpy {m['numpy']}; {m['date']}; command: `{res['command']}`; load average at the "
        f"start {m['load_average_1min']:.1f}."
    )


def markdown(res) -> str:
    out = [machine_line(res), ""]
    if "kinematics" in res:  # --only may leave a section out
        out += [
            "### Kinematic measures (KCI, sigma_min, dp_max, dw_max; full and reduced)",
            "",
            (
                "| wires | per-pose loop (poses/s) | vectorised NumPy (poses/s) | JAX (poses/s) | "
                "x loop | x NumPy | compile (s) | target |"
            ),
            "|---|---|---|---|---|---|---|---|",
        ]
    for r in res.get("kinematics", []):
        tgt = 3e6 if r["n_wires"] in (3, 4) else 1e6
        checks = [
            (f">= {tgt:.0e}/s", r["jax_poses_per_s"] >= tgt),
            ("300x loop", r["speedup_vs_loop"] >= 300),
            ("3x NumPy", r["speedup_vs_numpy"] >= 3),
            ("compile < 5 s", r["jax_compile_s"] < 5),
        ]
        status = ", ".join(f"{name}: {'met' if ok else 'MISSED'}" for name, ok in checks)
        out.append(
            f"| {r['n_wires']} | {r['loop_poses_per_s']:.3g} | {r['numpy_poses_per_s']:.3g}"
            f" | {r['jax_poses_per_s']:.3g} | {r['speedup_vs_loop']:.0f} | "
            f"{r['speedup_vs_numpy']:.1f} | {r['jax_compile_s']:.2f} | {status} |"
        )
    if "compliance" in res:
        out += [
            "",
            "### Compliance sweep (tension solve + stiffness + deflection)",
            "",
            (
                "| wires | per pose: SLSQP + NumPy (poses/s) | JAX batched (poses/s) | speed-up | "
                "SLSQP alone (poses/s) | x SLSQP alone | "
                "compile (s) | max rel. difference | target |"
            ),
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in res["compliance"]:
            out.append(
                f"| {r['n_wires']} | {r['scipy_poses_per_s']:.3g} | "
                f"{r['jax_poses_per_s']:.3g} | {r['speedup']:.0f} | "
                f"{r['slsqp_only_poses_per_s']:.3g} | {r['speedup_vs_slsqp_only']:.0f} | "
                f"{r['jax_compile_s']:.2f} | {r['max_rel_difference']:.1e} | "
                f"{'met' if r['speedup'] >= 1000 else 'MISSED'} (>= 1000x) |"
            )
    if "scaling" in res:
        out += [
            "",
            "### Scaling (4 wires, all 17 arrays kept, chunked sweep; `scaling.png`)",
            "",
            "Peak memory is the whole process's high-water mark (`VmHWM`), JAX included.",
            "",
            "| poses | time (s) | poses/s | peak memory (MB) |",
            "|---|---|---|---|",
        ]
        for r in res["scaling"]["rows"]:
            out.append(
                f"| {r['poses']:.2g} | {r['seconds']:.3g} | {r['poses'] / r['seconds']:.3g} | {r['peak_rss_mb']:.0f} |"
            )
        s = res["scaling"]["sharded_4_host_devices"]
        out.append(
            f"| {s['poses']:.2g} on {s['devices']} forced host devices | {s['seconds']:.3g} "
            f"| {s['poses'] / s['seconds']:.3g} | {s['peak_rss_mb']:.0f} |"
        )
    if "explore" in res:
        out += ["", "### Design-space exploration (4 wires, the paper's 18 x 145 grid)", "", markdown_explore(res)]
    for key, title in (("calibration", "Calibration"), ("optimiser", "Optimiser")):
        if key in res:
            out += ["", f"### {title}", "", "| what | seconds | note |", "|---|---|---|"]
            for r in res[key]:
                out.append(f"| {r['what']} | {r['seconds']:.3g} | {r.get('note', '')} |")
    return "\n".join(out)


def write_readme(md: str):
    from _readme import write_section

    write_section("RESULTS", md)


_CALIB_CHILD = textwrap.dedent("""
    import json, sys, tempfile, time
    sys.path.insert(0, sys.argv[1])
    from simulator import Truth, write_set
    from tension_zones.cli import main
    folder = tempfile.mkdtemp()
    csv, design = write_set(folder, "bench", Truth(n_wires=3, play=(0.25, 0.25, 0.25)), 500, seed=3)
    t0 = time.perf_counter()
    rc = main(["calibrate", str(csv), "--design", str(design), "--out", folder + "/out", "--quiet"])
    t = time.perf_counter() - t0
    rep = json.load(open(folder + "/out/report.json"))
    print(json.dumps({"seconds": t, "rc": rc, "effects": [e["name"] for e in rep["effects"]],
                      "rmse_after_mm": rep["rmse_after_mm"], "noise_floor_mm": rep["noise_floor_mm"]}))
""")


def bench_calibration(quick):
    """A 500-sample set from the project's own simulator (undeclared backlash), full library, a fresh
    process: what a lab engineer waits for, compile included."""
    r = subprocess.run(
        [sys.executable, "-c", _CALIB_CHILD, str(HERE.parent / "tests")],
        capture_output=True,
        text=True,
        timeout=1800,
        check=False,
    )
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-2000:])
    res = json.loads(r.stdout.strip().splitlines()[-1])
    note = (
        f"found {', '.join(res['effects']) or 'nothing'}; held-out RMSE "
        f"{res['rmse_after_mm']:.3f} mm (noise floor {res['noise_floor_mm']:.3f}); "
        f"target < 60 s: {'met' if res['seconds'] < 60 else 'MISSED'}"
    )
    return [{"what": "calibrate 500 samples, full library (cold process)", "seconds": res["seconds"], "note": note}]


def bench_optimiser(quick):
    """One optimiser run per wire count (free wire angles, full circle, deflection included)."""
    from tension_zones.design._optimise import optimize
    from tension_zones.design._scenario import parse_scenario

    rows = []
    for n in (3, 4, 5):
        sc = parse_scenario(
            {
                "n_wires": [n],
                "free_wire_angles": True,
                "theta_L_deg": [20.0, 80.0, 20.0],
                "delta_deg": [0.0, 350.0, 10.0],
                "optimizer": {"starts": 4, "steps": 50 if quick else 200},
            }
        )
        t0 = time.perf_counter()
        res = optimize(sc, progress=False)
        t_first = time.perf_counter() - t0
        t0 = time.perf_counter()
        optimize(sc, progress=False)
        t_again = time.perf_counter() - t0
        row = res["per_wire_count"][0]
        rows.append(
            {
                "what": f"optimise {n} wires ({sc.starts} starts x {sc.steps} steps, "
                f"{sc.theta_L.size * sc.delta.size} task poses)",
                "seconds": t_again,
                "note": f"first call {t_first:.1f} s (compile); objective {row['objective']:.3f}, "
                f"feasible {row['feasible']}",
            }
        )
    return rows


# ------------------------------------------------------------------------------------------------
# Design-space exploration
# ------------------------------------------------------------------------------------------------
def _explore_space(n_designs, loaded):
    """4 wires; pitch radius, length, wire stiffness and each wire's angle offset varied; a Halton
    sample of ``n_designs``; the paper's grid (theta_L 0..85 step 5, delta 0..360 step 2.5)."""
    return tz.parse_space(
        {
            "n_wires": 4,
            "pitch_radius_mm": [1.0, 3.0],
            "length_mm": [15.0, 30.0],
            "wire_stiffness_N_per_mm": [55.0, 105.0],
            "wire_angle_offset_deg": [-10, 10],
            "sample": {"method": "halton", "designs": n_designs},
            "load_N": [5.0, 0.0, 0.0] if loaded else None,
        }
    )


_EXPLORE_CHILD = textwrap.dedent("""
    import json, sys, time
    sys.path.insert(0, sys.argv[3])
    from run import _explore_space
    import tension_zones as tz
    space = _explore_space(int(sys.argv[1]), sys.argv[2] == "1")
    t0 = time.perf_counter()
    table = tz.explore(space, quiet=True)  # first call: compile included
    t = time.perf_counter() - t0
    hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
    print(json.dumps({"designs": int(table["design"].size), "seconds_with_compile": t,
                      "peak_rss_mb": int(hwm) / 1024,
                      "table_mb": sum(v.nbytes for v in table.values()) / 2**20}))
""")


def _loop_over_designs(space, rows, chunk_size=None):
    """Today's way: one ``sweep_grid`` per design, each design's arrays reduced with NumPy into the
    same statistics (the kinematic measures, plus the statics with a load)."""
    from tension_zones.analysis._sweep import DEFAULT_CHUNK, sweep_grid
    from tension_zones.design._explore import _kinematic_pose, _loaded_pose, _stats
    from tension_zones.model._statics import as_wrench

    loaded = space.load is not None
    fn, args = (_loaded_pose, (space.dq, as_wrench(space.load))) if loaded else (_kinematic_pose, (space.dq,))
    reduce = {"max": np.max, "min": np.min, "mean": np.mean, "nanmax": np.nanmax, "nanmean": np.nanmean}
    cols = space.columns(4)
    out = []
    for i in rows:
        d = tz.Design(
            4,
            cols["length_mm"][i],
            cols["pitch_radius_mm"][i],
            wire_angles=np.radians([cols[f"wire_angle_{k}_deg"][i] for k in range(1, 5)]),
            wire_stiffness=cols["wire_stiffness_N_per_mm"][i],
        )
        res = sweep_grid(fn, d, space.theta_L, space.delta, *args, quiet=True, chunk_size=chunk_size or DEFAULT_CHUNK)
        out.append([reduce[op](res[key].astype(float)) for _, key, op in _stats(loaded)])
    return np.array(out)


def bench_explore(quick):
    """10^4 designs x the paper's grid: the exploration engine against a Python loop over designs
    calling ``sweep_grid`` (timed on 40 designs and extrapolated; once with its default chunk, once
    with the chunk set to the grid's size); compile time (the first call, on one design); peak
    memory of fresh processes exploring 10^3, 10^4 and 10^5 designs."""
    n_designs = 10**3 if quick else 10**4
    n_loop = 40
    rows = {}
    for loaded in (False, True):
        space = _explore_space(n_designs, loaded)
        n_poses = space.theta_L.size * space.delta.size
        subset = np.linspace(0, n_designs - 1, n_loop).astype(int)
        # compile: the first call on one design (the same program: a chunk is padded to 128 designs)
        compile_s = _seconds(lambda: tz.explore(_explore_space(1, loaded), quiet=True))  # noqa: B023
        table = tz.explore(space, quiet=True)
        # the loop's statistics are the engine's (a check, not a timing)
        ref = _loop_over_designs(space, subset[:4])
        from tension_zones.design._explore import _stats

        ours = np.array([[table[c][i] for c, _, _ in _stats(loaded)] for i in subset[:4]])
        agree = float(np.nanmax(np.abs(ours - ref) / np.maximum(np.abs(ref), 1e-300)))
        _loop_over_designs(space, subset[:2], chunk_size=n_poses)  # warm-up of the matched chunk
        t_e, t_l, t_m = [], [], []
        for _ in range(2 if quick else 3):  # interleaved, as the other sections
            t_e.append(_seconds(lambda: tz.explore(space, quiet=True)))  # noqa: B023
            t_l.append(_seconds(lambda: _loop_over_designs(space, subset)))  # noqa: B023
            t_m.append(_seconds(lambda: _loop_over_designs(space, subset, chunk_size=n_poses)))  # noqa: B023
        t_explore = statistics.median(t_e)
        rows["loaded" if loaded else "kinematic"] = {
            "designs": n_designs,
            "poses_per_design": n_poses,
            "explore_s": t_explore,
            "explore_compile_s": compile_s,
            "explore_designs_per_s": n_designs / t_explore,
            "explore_pose_evals_per_s": n_designs * n_poses / t_explore,
            "loop_designs_timed": n_loop,
            "loop_designs_per_s": n_loop / statistics.median(t_l),
            "loop_chunk_matched_designs_per_s": n_loop / statistics.median(t_m),
            "speedup_vs_loop": statistics.median((a / n_loop) / (b / n_designs) for a, b in zip(t_l, t_e)),
            "speedup_vs_loop_chunk_matched": statistics.median(
                (a / n_loop) / (b / n_designs) for a, b in zip(t_m, t_e)
            ),
            "max_rel_difference_vs_loop": agree,
        }
    env = dict(os.environ)
    memory = []
    for n in (10**3, 10**4) if quick else (10**3, 10**4, 10**5):
        r = subprocess.run(
            [sys.executable, "-c", _EXPLORE_CHILD, str(n), "0", str(HERE)],
            env=env,
            capture_output=True,
            text=True,
            timeout=3600,
            check=False,
        )
        if r.returncode != 0:
            raise RuntimeError(r.stderr[-2000:])
        memory.append(json.loads(r.stdout.strip().splitlines()[-1]))
    return {**rows, "memory": memory}


def markdown_explore(res) -> str:
    """The explore section's table (``benchmarks/README.md`` takes it by hand: its numbers come
    from their own run)."""
    e = res["explore"]
    out = [
        (
            "| statistics | designs x poses | explore: designs/s | explore: pose-evals/s | loop of "
            "`sweep_grid`: designs/s | loop, chunk = grid: designs/s | x loop | x loop (chunk = grid) | "
            "compile (s) | max rel. difference |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for kind in ("kinematic", "loaded"):
        r = e[kind]
        loop_pe = r["loop_designs_per_s"] * r["poses_per_design"]
        out.append(
            f"| {kind} | {r['designs']:.0e} x {r['poses_per_design']} | "
            f"{r['explore_designs_per_s']:.3g} | {r['explore_pose_evals_per_s']:.3g} | "
            f"{r['loop_designs_per_s']:.3g} ({loop_pe:.3g} pose-evals/s) | "
            f"{r['loop_chunk_matched_designs_per_s']:.3g} | {r['speedup_vs_loop']:.1f} | "
            f"{r['speedup_vs_loop_chunk_matched']:.1f} | {r['explore_compile_s']:.1f} | "
            f"{r['max_rel_difference_vs_loop']:.1e} |"
        )
    out += [
        "",
        ("| designs (kinematic, fresh process) | time incl. compile (s) | peak memory (MB) | table (MB) |"),
        "|---|---|---|---|",
    ]
    for m in e["memory"]:
        out.append(
            f"| {m['designs']:.0e} | {m['seconds_with_compile']:.3g} | {m['peak_rss_mb']:.0f} | {m['table_mb']:.2f} |"
        )
    return "\n".join(out)


def bench_robots(quick):
    """Robots of one, two and three segments side by side: the kinematic measures (full and reduced,
    exact bounds) per configuration, the one segment on its theta_L x delta grid and the robots on
    Halton configurations; the three segments with the tension-only statics too."""
    from tension_zones.analysis import config_metrics, config_samples, pose_metrics, sweep_configs, sweep_grid
    from tension_zones.model import config_compliance

    def with_statics(robot, B, dq, w):
        return {**config_metrics(robot, B, dq), **config_compliance(robot, B, w)}

    wrench = np.array([0.0, 0.0, -0.5, 0.0, 0.0, 0.0])
    th, de = grid(1.0, 1.0) if quick else grid(0.5, 0.25)
    seg = tz.Design(4, 20.0, 2.0)
    cases = [
        ("1 segment, 4 wires (grid)", th.size * de.size, lambda: sweep_grid(pose_metrics, seg, th, de, 0.4, quiet=True))
    ]
    for label, path, n, statics in (
        ("2 segments, 3 + 3 wires", "design/two_segments.design.json", 1 << (13 if quick else 16), False),
        ("3 segments, 3 x 3 wires (FTDCR v4)", "ftdcr_v4/design.json", 1 << (13 if quick else 16), False),
        ("3 segments, 3 x 3 wires, with statics", "ftdcr_v4/design.json", 1 << (10 if quick else 12), True),
    ):
        robot = tz.Robot.from_json(tz.example_path(path))
        B = config_samples(robot.n_segments, n, 90.0)
        fn, extra = (with_statics, (0.4, wrench)) if statics else (config_metrics, (0.4,))
        cases.append((label, n, lambda r=robot, B=B, fn=fn, extra=extra: sweep_configs(fn, r, B, *extra, quiet=True)))
    firsts = [_seconds(run) for _, _, run in cases]
    times: list[list[float]] = [[] for _ in cases]
    for _ in range(2 if quick else 3):  # interleaved: every case once per repeat
        for i, (_, _, run) in enumerate(cases):
            times[i].append(_seconds(run))
    rows = []
    for (label, n, _), first, t in zip(cases, firsts, times):
        med = statistics.median(t)
        rows.append({"case": label, "configurations": n, "per_s": n / med, "compile_s": max(first - med, 0.0)})
    return {"sweeps": rows, "bounds": bench_bounds(quick)}


def bench_bounds(quick):
    """The exact tip bound's two enumerations side by side per wire count (one bound, random
    generators, a chunk of ``ROBOT_CHUNK`` vmapped): where ``zonotope_max_sq`` switches from the
    box's vertices to the face edges (``BOX_VERTICES_MAX``)."""
    import jax

    from tension_zones.analysis._chain import BOX_VERTICES_MAX, _box_vertices_max_sq, _face_edges_max_sq
    from tension_zones.analysis._sweep import ROBOT_CHUNK

    rng = np.random.default_rng(0)
    out = []
    for n in (6, 9, 10, 11, 12, 13, 14, 15, 16):
        G = jax.device_put(rng.normal(size=(ROBOT_CHUNK, 3, n)))
        row = {"wires": n, "box_vertices_max": BOX_VERTICES_MAX}
        for key, fn in (("box_us", _box_vertices_max_sq), ("faces_us", _face_edges_max_sq)):
            f = jax.jit(jax.vmap(fn))
            run = lambda f=f, G=G: jax.block_until_ready(f(G))
            run()
            row[key] = min(_seconds(run) for _ in range(3 if quick else 10)) / ROBOT_CHUNK * 1e6
        out.append(row)
    return out


def markdown_robots(res) -> str:
    out = [
        "| robot | configurations | configurations/s | compile (s) | target |",
        "|---|---|---|---|---|",
    ]
    for r in res["sweeps"]:
        target = ""
        if r["case"].startswith("3 segments") and "statics" not in r["case"]:
            target = f">= 5e+05/s: {'met' if r['per_s'] >= 5e5 else 'MISSED'}"
        out.append(f"| {r['case']} | {r['configurations']:,} | {r['per_s']:.3g} | {r['compile_s']:.2f} | {target} |")
    out += [
        "",
        (
            "One exact bound, us per configuration (vmapped over a chunk, one thread's program): every vertex "
            "pair of the box against the ends of the zonotope's face edges. `zonotope_max_sq` takes the box up "
            f"to `BOX_VERTICES_MAX` = {res['bounds'][0]['box_vertices_max']} wires."
        ),
        "",
        "| wires | box vertices | face edges |",
        "|---|---|---|",
    ]
    out += [f"| {r['wires']} | {r['box_us']:.3g} | {r['faces_us']:.3g} |" for r in res["bounds"]]
    return "\n".join(out)


def bench_hysteresis(quick):
    """``hysteresis.py``'s table: measured pairs of one command against the calibrated robots' bounds
    (the forced-backlash calibration of FTDCR v6 runs here, in a temporary folder)."""
    import tempfile

    import hysteresis

    with tempfile.TemporaryDirectory() as tmp:
        return {"table": hysteresis.table(hysteresis.measure_all(Path(tmp) / "forced"))}


SECTIONS = {
    "kinematics": bench_kinematics,
    "compliance": bench_compliance,
    "scaling": bench_scaling,
    "calibration": bench_calibration,
    "optimiser": bench_optimiser,
    "explore": bench_explore,
    "robots": bench_robots,
    "hysteresis": bench_hysteresis,
}
#: Sections with a block of their own in benchmarks/README.md (the others share RESULTS): marker,
#: title, renderer, and whether the block starts with the machine line (timings do).
OWN_BLOCK = {
    "robots": ("ROBOTS", "Robots of several segments: measures per configuration", markdown_robots, True),
    "hysteresis": ("HYSTERESIS", "The bounds meet hardware: one command, two histories", lambda r: r["table"], False),
}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="smaller grids, fewer repeats, no 1e7 sweep")
    p.add_argument("--json", help="write every number to this JSON file")
    p.add_argument("--no-readme", action="store_true", help="do not rewrite benchmarks/README.md")
    p.add_argument("--only", nargs="*", choices=sorted(SECTIONS), help="run only these sections")
    args = p.parse_args(argv)
    command = "python benchmarks/run.py" + (" --quick" if args.quick else "")
    res = {"machine": machine(), "command": command + (f" --only {' '.join(args.only)}" if args.only else "")}
    for name, fn in SECTIONS.items():
        if args.only and name not in args.only:
            continue
        print(f"[bench] {name} ...", flush=True)
        res[name] = fn(args.quick)
        print(json.dumps(res[name], indent=1, default=float), flush=True)
    if "scaling" in res:
        plot_scaling(res["scaling"], HERE / "scaling.png")
    from _readme import write_section

    for name, (block, title, render, timed) in OWN_BLOCK.items():
        if name in res:
            md_own = f"{machine_line(res)}\n\n{render(res[name])}" if timed else render(res[name])
            print(md_own)
            if not args.no_readme:
                write_section(block, md_own, title)
    if any(name in res for name in SECTIONS if name not in OWN_BLOCK):
        md = markdown(res)
        print(md)
        if not args.no_readme:
            write_readme(md)
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2, default=float))


if __name__ == "__main__":
    main()
