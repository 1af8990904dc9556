"""The rod model: speed per sample and accuracy against pieces, side by side in one run.

    python benchmarks/rod.py [--no-readme]

For 1, 2, 4 and 8 pieces per segment: the equilibrium and tip of 1000 samples (one ``vmap``,
compiled once, best of three runs), with and without a weight, and its Jacobian in three parameters
(forward mode through the implicit derivative), for one 60 mm segment and the three-segment FTDCR v4
robot; and the tip error against the independent Kirchhoff-rod solution of ``tests/reference_rod.py``
(SciPy's ``solve_bvp``, the same tendon tensions) for a segment under its weight and under a lateral
tip force. Results go into ``benchmarks/README.md`` between the ``ROD`` markers.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import tension_zones as tz
from tension_zones.model import Load
from tension_zones.model import _equilibrium as E
from tension_zones.model._robot import Structure, chain_tip

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
N = 1000
PIECES = (1, 2, 4, 8)


def best(f, *a, n=3):
    jax.block_until_ready(f(*a))
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        jax.block_until_ready(f(*a))
        ts.append(time.perf_counter() - t0)
    return min(ts)


def speed(robot, m, weight):
    st = Structure(robot.n_wires_per_segment, m)
    rng = np.random.default_rng(0)
    Q = jnp.asarray(rng.uniform(-2.0, 0.5, (N, robot.n_wires)))
    g = jnp.array([0.0, 0.0, -weight])

    def tips(ph):
        B = jax.vmap(lambda q: E.solve(ph, st, q, jnp.zeros(3)))(Q)
        L = E.piece_lengths(ph, st)
        return jax.vmap(lambda b: chain_tip(L, b)[0])(B)

    phys = robot.params()
    phys["gravity"] = g
    f = jax.jit(tips)
    t0 = time.perf_counter()
    jax.block_until_ready(f(phys))
    compile_s = time.perf_counter() - t0
    J = jax.jit(jax.jacfwd(lambda ei: tips({**phys, "EI": ei})))
    return {
        "compile_s": compile_s,
        "us_per_sample": best(f, phys) / N * 1e6,
        "jac_us_per_sample": best(J, phys["EI"]) / N * 1e6,
    }


def accuracy():
    import reference_rod as rr

    seg = tz.Design(3, 60.0, 4.5, wire_stiffness=50.0, backbone_EI=2454.0)
    robot, q = tz.Robot(seg), jnp.array([-3.0, 0.5, 0.5])
    rows = {}
    for name, load, gj in (
        ("weight 0.003 N/mm", Load(jnp.zeros(3), jnp.array([0.003, 0.0, 0.0])), None),
        (
            "lateral tip force 0.4 N (rigid torsion)",
            Load(jnp.array([0.0, 0.4, -0.2]), jnp.array([0.002, 0.0, -0.002])),
            1e9,
        ),
    ):
        errs = []
        for m in PIECES + (16,):
            phys = robot.params()
            phys["gravity"] = load.gravity
            st = Structure((3,), m)
            B = E.solve(phys, st, q, load.tip_force)
            p = np.asarray(chain_tip(E.piece_lengths(phys, st), B)[0])
            sm = E._Sample(phys, st, q, load.tip_force, jnp.zeros(3), jnp.asarray(True))
            tau = np.asarray(sm.k * jnp.maximum(sm.stretch(B.reshape(-1)), 0.0))
            ref = rr.solve_segment(
                60.0,
                2454.0,
                np.asarray(seg.wire_angles),
                4.5,
                tau,
                weight=np.asarray(load.gravity),
                tip_force=np.asarray(load.tip_force),
                GJ=gj,
            )
            errs.append(float(np.linalg.norm(p - ref.tip_position)))
        rows[name] = errs
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--no-readme", action="store_true")
    args = p.parse_args(argv)
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    load0 = os.popen("uptime").read().strip()
    robots = {
        "1 segment (60 mm, 3 wires)": tz.Robot(tz.Design(3, 60.0, 4.5, wire_stiffness=50.0, backbone_EI=2454.0)),
        "FTDCR v4 (3 segments, 9 wires)": tz.Robot.from_json(tz.example_path("ftdcr_v4/design.json")),
    }
    lines = [
        (
            f"`python benchmarks/rod.py`, started {started} ({load0}); {N} samples per call, float64, "
            "best of three after compilation."
        ),
        "",
        "| robot | pieces per segment | load | compile (s) | tip, us/sample | Jacobian in 3 parameters, us/sample |",
        "|---|---:|---|---:|---:|---:|",
    ]
    for name, robot in robots.items():
        for m in PIECES:
            for w in (0.0, 0.003):
                r = speed(robot, m, w)
                lines.append(
                    f"| {name} | {m} | {'weight' if w else 'none'} | {r['compile_s']:.1f} | "
                    f"{r['us_per_sample']:.1f} | {r['jac_us_per_sample']:.1f} |"
                )
                print(lines[-1], flush=True)
    acc = accuracy()
    lines += [
        "",
        (
            "Tip error (mm) against the Kirchhoff rod (`tests/reference_rod.py`, same tendon tensions), "
            "60 mm segment, EI 2454 N mm^2:"
        ),
        "",
        "| load | " + " | ".join(f"{m} pieces" for m in PIECES + (16,)) + " |",
        "|---|" + "---:|" * (len(PIECES) + 1),
    ]
    for name, errs in acc.items():
        lines.append(f"| {name} | " + " | ".join(f"{e:.4f}" for e in errs) + " |")
    md = "\n".join(lines)
    print(md)
    if not args.no_readme:
        from _readme import write_section

        write_section("ROD", md, title="The rod model")


if __name__ == "__main__":
    main()
