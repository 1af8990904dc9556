"""Compile time of one sweep chunk against the wire count (large wire counts).

    python benchmarks/compile_scaling.py [--wires 3 4 8 16 32 64] [--measure kinematics compliance]
                                         [--timeout 300] [--json OUT.json]

Each (wire count, measure) runs in a fresh process (no compilation cache shared between cases, and a
case that runs past ``--timeout`` seconds is stopped and reported as such). Timed: tracing and
lowering (Python and JAX), XLA compilation, and one run of the compiled chunk (16,384 poses,
float64), for the per-pose function ``tension-zones sweep`` evaluates: ``pose_metrics``
(kinematics) or ``pose_metrics`` plus ``compliance_pose`` (``--compliance``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

CHILD = r"""
import json, sys, time
import numpy as np
import jax, jax.numpy as jnp
import tension_zones as tz
from tension_zones.analysis._metrics import pose_metrics
from tension_zones.model._statics import compliance_pose

n, measure = int(sys.argv[1]), sys.argv[2]
d = tz.Design(n, 20.0, 2.0, wire_stiffness=75.0, backbone_EI=1200.0)
w = jnp.asarray([5.0, 0.0, 0.0, 0.0, 0.0, 0.0])

def fn(design, t, de, dq, w):
    out = pose_metrics(design, t, de, dq)
    if measure == "compliance":
        out = {**out, **compliance_pose(design, t, de, w)}
    return out

chunk = 1 << 14
rng = np.random.default_rng(0)
th = jnp.asarray(rng.uniform(0.0, 1.5, chunk)); de = jnp.asarray(rng.uniform(0.0, 6.3, chunk))
f = jax.jit(lambda design, th, de, dq, w: jax.vmap(lambda a, b: fn(design, a, b, dq, w))(th, de))
t0 = time.perf_counter(); lowered = f.trace(d, th, de, 0.4, w).lower()
t1 = time.perf_counter(); compiled = lowered.compile()
t2 = time.perf_counter(); jax.block_until_ready(compiled(d, th, de, 0.4, w))
t3 = time.perf_counter(); jax.block_until_ready(compiled(d, th, de, 0.4, w))
t4 = time.perf_counter()
print(json.dumps({"n": n, "measure": measure, "trace_lower_s": t1 - t0, "compile_s": t2 - t1,
                  "run_s": t4 - t3, "poses_per_s": chunk / (t4 - t3)}))
"""


def run_case(n: int, measure: str, timeout: float) -> dict:
    t0 = time.perf_counter()
    try:
        r = subprocess.run(
            [sys.executable, "-c", CHILD, str(n), measure], capture_output=True, check=False, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        return {"n": n, "measure": measure, "error": f"stopped after {timeout:g} s"}
    if r.returncode != 0:
        last = (r.stderr.strip().splitlines() or ["?"])[-1]
        return {"n": n, "measure": measure, "error": last[:200], "wall_s": time.perf_counter() - t0}
    out = json.loads(r.stdout.strip().splitlines()[-1])
    out["wall_s"] = time.perf_counter() - t0
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--wires", type=int, nargs="+", default=[3, 4, 8, 16, 32, 64])
    p.add_argument("--measure", nargs="+", choices=("kinematics", "compliance"), default=["kinematics", "compliance"])
    p.add_argument("--timeout", type=float, default=300.0)
    p.add_argument("--json")
    args = p.parse_args(argv)
    rows = []
    print("| measure | wires | trace + lower (s) | XLA compile (s) | chunk run (s) | poses/s | process wall (s) |")
    print("|---|---|---|---|---|---|---|")
    for m in args.measure:
        for n in args.wires:
            r = run_case(n, m, args.timeout)
            rows.append(r)
            if "error" in r:
                print(f"| {m} | {n} | {r['error']} | | | | |", flush=True)
            else:
                print(
                    f"| {m} | {n} | {r['trace_lower_s']:.2f} | {r['compile_s']:.2f} | "
                    f"{r['run_s']:.4f} | {r['poses_per_s']:.3g} | {r['wall_s']:.1f} |",
                    flush=True,
                )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
