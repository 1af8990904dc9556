"""Design optimiser: wire count, pitch radius, wire stiffness and wire placement.

Objective for one wire count ``n`` (all terms over the scenario's task grid of poses):

    w_p * max dp_max_reduced  +  w_d * max |dx|_reduced  +  w_n * n

with ``dp_max_reduced`` the reduced-Jacobian position-uncertainty bound (paper Sec. 4, Eq. 19) and
``|dx|_reduced`` the reduced compliance deflection under the scenario's load (paper Sec. 5).

**Controllability is a constraint.** The pinv-based bound rewards slack wires (a direction nobody
actuates drops out of ``pinv``), so a design is feasible only if over the task's range of bending
directions the taut wires span the configuration space: ``spread >= min_spread`` where ``spread``
is the smallest singular value of the taut wires' unit vectors ``[cos delta_k, sin delta_k]``,
checked exactly over the continuous range (it is constant on each sector of constant taut set), so
a design cannot pass by dodging the grid. By default only sectors of finite width count: the
isolated directions where a wire sits exactly on its zone boundary (four even wires: the lines
through a wire) are reported (``zero_width_directions_deg``), not violations; the scenario key
``strict_controllability`` counts them too (the grid directions and every zone boundary, see
:func:`_range_spread`). The rule and its reasons: ``README.md`` beside this module. It enters the
optimisation as a quadratic penalty through the straight-through tension masks, and violations are
reported.

Variables map onto the feasible set exactly: the pitch radius and wire stiffness are box variables
scaled to [0, 1] and projected after every step (their bounds already include the outer-diameter
and wire-gap limits, and an optimum on a bound is reached exactly), free wire angles as a start angle plus gaps that are each at
least the minimum angular separation (softmax of the slack), inside the allowed arc when a tool
channel forbids part of the circle. Gradients: Adam (optax) on a log-sum-exp surrogate of each
worst case whose sharpness rises geometrically over the run (continuation); the **exact** maximum
is what is reported, and the best exact objective seen is kept. Several random starts run together
(``vmap``); each wire count is optimised and the best count reported.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._numerics import compact_programs
from .._xla import fast_compile_options
from ..model._design import Design
from ..model._zones import tension_mask
from ._scenario import Scenario

#: Penalty weight on the mean squared controllability violation (objective units per unit^2).
SPREAD_PENALTY = 1e3
#: Added per violating pose when ranking iterates, so any feasible design beats any infeasible one.
INFEASIBLE_RANK = 1e6


# ---------------------------------------------------------------------------------------------
# Parametrisation: unconstrained z -> a Design that satisfies every geometric constraint
# ---------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _Bounds:
    """Numbers of one wire count's search space (a pytree of arrays: new values never recompile)."""

    r_lo: jax.Array
    r_hi: jax.Array
    k_lo: jax.Array
    k_hi: jax.Array
    sep: jax.Array  # wire diameter + gap (mm): chord between neighbouring wire centres >= sep
    clear: jax.Array  # wire radius + gap (mm): chord from a wire centre to a forbidden arc >= clear
    arc_start: jax.Array  # allowed arc (rad): [arc_start, arc_start + arc_len]
    arc_len: jax.Array


jax.tree_util.register_dataclass(_Bounds, data_fields=[f.name for f in dataclasses.fields(_Bounds)], meta_fields=[])


def _min_angle(chord, r):
    """Smallest angle between two points on a circle of radius r whose chord is at least `chord`."""
    return 2.0 * jnp.arcsin(jnp.clip(chord / (2.0 * r), 0.0, 1.0))


def _angles(z_a0, z_gaps, r, b: _Bounds, n: int, free: bool, arc: bool):
    """Wire angles (n,) from unconstrained variables; every gap >= the minimum separation."""
    if not free:
        return jnp.arange(n) * (2.0 * jnp.pi / n)
    s_min = _min_angle(b.sep, r)
    if not arc:
        # n gaps around the full circle, each s_min + a share of the slack
        gaps = s_min + (2.0 * jnp.pi - n * s_min) * jax.nn.softmax(z_gaps[:n])
        return z_a0 + jnp.concatenate([jnp.zeros(1), jnp.cumsum(gaps[:-1])])
    # inside the allowed arc: end clearance h at both ends, n - 1 inner gaps >= s_min
    h = _min_angle(2.0 * b.clear, r) / 2.0
    slack = b.arc_len - 2.0 * h - (n - 1) * s_min
    parts = slack * jax.nn.softmax(z_gaps)  # n + 1 parts: before, between, after
    steps = jnp.concatenate([b.arc_start + h + parts[:1], s_min + parts[1:n]])
    return jnp.cumsum(steps)


def _design(z, b: _Bounds, n: int, free: bool, arc: bool, base: Design) -> Design:
    # r and k are box variables in [0, 1] (projected after every step, so a bound is reachable)
    r = b.r_lo + (b.r_hi - b.r_lo) * z["r"]
    k = b.k_lo + (b.k_hi - b.k_lo) * z["k"]
    angles = _angles(z["a0"], z["gaps"], r, b, n, free, arc)
    return base.replace(pitch_radius=r, wire_stiffness=k, wire_angles=angles)


# ---------------------------------------------------------------------------------------------
# Controllability
# ---------------------------------------------------------------------------------------------
def spread(design: Design, delta):
    """Smallest singular value of the taut wires' unit vectors ``[cos d_k, sin d_k]`` at ``delta``.

    0 with one taut wire (or none); 1/sqrt(2)*... grows as the taut wires spread out. Uses the
    straight-through tension mask, so it has a gradient w.r.t. the wire angles.
    """
    dk = delta + design.wire_angles
    m = tension_mask(design, delta)
    c, s = jnp.cos(dk), jnp.sin(dk)
    half_tr = 0.5 * jnp.sum(m * (c * c + s * s))
    # det of the 2x2 Gram by Cauchy-Binet: exactly 0 with fewer than two taut wires
    i, j = jnp.triu_indices(design.n_wires, k=1)
    det = jnp.sum(m[i] * m[j] * (c[i] * s[j] - s[i] * c[j]) ** 2)
    # (tr/2)^2 - det written as a sum of squares, accurate near a double eigenvalue
    disc = (0.5 * jnp.sum(m * jnp.cos(2 * dk))) ** 2 + (0.5 * jnp.sum(m * jnp.sin(2 * dk))) ** 2
    root = jnp.sqrt(jnp.where(disc > 0, disc, 1.0)) * (disc > 0)
    big = half_tr + root  # larger eigenvalue; the smaller one is det / big (no cancellation)
    lam_min = jnp.where(big > 0, det / jnp.where(big > 0, big, 1.0), 0.0)
    return jnp.sqrt(jnp.where(lam_min > 0, lam_min, 1.0)) * (lam_min > 0)


# ---------------------------------------------------------------------------------------------
# Objective
# ---------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _Task:
    """The scenario's numbers as arrays (a pytree: new values of the same shapes never recompile)."""

    theta_L: jax.Array  # (n_theta,)
    delta: jax.Array  # (n_delta,)
    dq: jax.Array
    load: jax.Array  # (3,)
    w_position: jax.Array
    w_deflection: jax.Array
    w_wires: jax.Array
    min_spread: jax.Array
    delta_lo: jax.Array  # the task's continuous range of bending directions (rad)
    delta_span: jax.Array
    strict: jax.Array  # bool: directions of zero width count as violations too


jax.tree_util.register_dataclass(_Task, data_fields=[f.name for f in dataclasses.fields(_Task)], meta_fields=[])


def _pose_terms(design: Design, theta_L, delta, task: _Task, with_defl: bool = True):
    """(dp_max (mm), reduced deflection (mm), statics feasible) at one pose.

    dp_max: reduced-Jacobian position-uncertainty bound (paper Eq. 19, metrics.pose_measures);
    deflection: reduced compliance under the scenario's load (paper Eq. 31, statics).
    """
    from ..analysis._metrics import pose_measures
    from ..model._statics import compliance_pose

    mask = tension_mask(design, delta)
    dp = pose_measures(design, theta_L, delta, task.dq, mask=mask)["dp_max"]
    if not with_defl:  # static: a zero deflection weight skips the statics entirely
        return dp, jnp.zeros_like(dp), jnp.ones_like(dp, dtype=bool)
    c = compliance_pose(design, theta_L, delta, task.load)
    ok = c["feasible"] & jnp.isfinite(c["deflection_mm_reduced"])
    defl = jnp.where(ok, c["deflection_mm_reduced"], 0.0)  # double-where: no NaN in gradients
    return dp, defl, ok


def zone_boundaries(design: Design):
    """The 2n bending directions (rad) where a wire enters or leaves its zone: ``-alpha_k +- pi/2``."""
    a = design.wire_angles
    return jnp.concatenate([-a + jnp.pi / 2, -a - jnp.pi / 2])


#: Sectors of constant taut set no wider than this (rad) are single directions: zone boundaries that
#: coincide up to rounding (four even wires: wire k's end and wire k + 2's start).
ZERO_WIDTH_RAD = 1e-9


def _range_spread(design: Design, task: _Task):
    """Spread at the task grid's directions and at every zone boundary inside the task's range
    (the strict rule: every direction, zero width included).

    The spread is invariant to rotating all wires, so along delta it only changes where the taut
    set does; at a boundary the boundary wire is slack (tension_zones/MODEL.md rule), the taut set is the
    intersection of its neighbours' and the spread their minimum. The minimum over the continuous
    range is therefore attained on this finite set: the check is exact, not just on grid points.
    """
    on_grid = jax.vmap(lambda d: spread(design, d))(task.delta)
    bnd = zone_boundaries(design)
    inside = jnp.mod(bnd - task.delta_lo, 2 * jnp.pi) <= task.delta_span + 1e-12
    at_bnd = jax.vmap(lambda d: spread(design, d))(bnd)
    return jnp.concatenate([on_grid, jnp.where(inside, at_bnd, jnp.inf)])


def _sector_spread(design: Design, task: _Task):
    """Spread on every sector of finite width that overlaps the task's range with finite width
    (the default rule), ``inf`` for the others; (2n,).

    The 2n zone boundaries cut the circle into sectors of constant taut set, so the spread is
    constant on each and is taken at its middle. Sectors of zero width (coinciding boundaries:
    single directions) and sectors that touch the range only at an end are left out.
    """
    start = jnp.sort(jnp.mod(zone_boundaries(design), 2 * jnp.pi))
    width = jnp.concatenate([start[1:], start[:1] + 2 * jnp.pi]) - start
    rel = jnp.mod(start - task.delta_lo, 2 * jnp.pi)  # the sector's start, from the range's start
    tol = ZERO_WIDTH_RAD
    overlaps = (rel < task.delta_span - tol) | (rel + width > 2 * jnp.pi + tol)
    at_mid = jax.vmap(lambda d: spread(design, d))(start + 0.5 * width)
    return jnp.where((width > ZERO_WIDTH_RAD) & overlaps, at_mid, jnp.inf)


def _controllability(design: Design, task: _Task):
    """``(penalty, violations, smallest spread)`` of the rule the task asks for (``task.strict``):
    the mean squared shortfall below ``min_spread``, the number of checked directions or sectors
    below it, and the smallest spread checked. A task range of zero width (one direction) is
    always checked strictly: that direction is all the task needs."""
    results = []
    for spr in (_range_spread(design, task), _sector_spread(design, task)):
        viol = jnp.maximum(task.min_spread - spr, 0.0)  # 0 for unchecked entries (inf)
        results.append((jnp.mean(viol**2), jnp.sum(spr < task.min_spread), jnp.min(spr)))
    strict = task.strict | (task.delta_span <= ZERO_WIDTH_RAD)
    return tuple(jnp.where(strict, a, b) for a, b in zip(*results))


def _grid_terms(design: Design, task: _Task, with_defl: bool = True):
    """Per-pose terms on the task grid, each (n_theta, n_delta), and the controllability check."""
    inner = jax.vmap(lambda t, d: _pose_terms(design, t, d, task, with_defl), in_axes=(None, 0))
    dp, defl, ok = jax.vmap(inner, in_axes=(0, None))(task.theta_L, task.delta)
    return dp, defl, ok, _controllability(design, task)


def _smooth_max(x, sharpness):
    """Log-sum-exp upper bound of max(x) with the relative temperature t = max|x| / sharpness.

    ``max(x) <= smooth <= max(x) + t log(size)``. The shift by the (stop-gradient) maximum only
    guards against overflow; it leaves value and gradient unchanged.
    """
    x = x.ravel()
    m = jax.lax.stop_gradient(jnp.max(x))
    t = jnp.maximum(jnp.max(jnp.abs(x)), 1e-12) / sharpness
    return m + t * jnp.log(jnp.sum(jnp.exp((x - m) / t)))


def _objective(design: Design, task: _Task, n: int, sharpness, with_defl: bool = True):
    """(smooth objective for gradients, exact objective, exact pieces).

    Traced in the compact forms (:func:`~tension_zones._numerics.compact_programs`): the optimiser's
    program takes far longer to compile than to run, and the compact forms compile faster.
    """
    with compact_programs():
        dp, defl, ok, (shortfall, violations, min_spread) = _grid_terms(design, task, with_defl)
    # poses the wires cannot hold without pushing count as a controllability violation too
    penalty = SPREAD_PENALTY * (shortfall + jnp.mean(1.0 - ok))
    wire_cost = task.w_wires * n
    smooth = (
        task.w_position * _smooth_max(dp, sharpness)
        + task.w_deflection * _smooth_max(defl, sharpness)
        + wire_cost
        + penalty
    )
    worst_dp, worst_defl = jnp.max(dp), jnp.max(defl)
    exact = task.w_position * worst_dp + task.w_deflection * worst_defl + wire_cost
    pieces = {
        "worst_dp": worst_dp,
        "worst_defl": worst_defl,
        "min_spread": min_spread,
        "violations": violations,
        "statics_infeasible": jnp.sum(~ok),
    }
    return smooth, exact, pieces


#: :func:`_objective`, compiled once per wire count and task shape (not once per call).
_objective_jit = jax.jit(_objective, static_argnums=(2, 4), compiler_options=fast_compile_options())


def _task(sc: Scenario) -> _Task:
    f = lambda x: jnp.asarray(x, float)
    return _Task(
        f(sc.theta_L),
        f(sc.delta),
        f(sc.dq),
        f(sc.load),
        f(sc.w_position),
        f(sc.w_deflection),
        f(sc.w_wires),
        f(sc.min_spread),
        f(sc.delta[0]),
        f(_span(sc)),
        jnp.asarray(sc.strict_controllability),
    )


def _span(sc: Scenario) -> float:
    """Width (rad) of the task's range of bending directions, at most a full circle."""
    return min(float(sc.delta[-1] - sc.delta[0]), 2 * math.pi)


#: :func:`spread` as one program per wire count: run op by op it would compile each of its
#: operations, for a handful of values
_spread_jit = jax.jit(spread)


def zero_width_directions(sc: Scenario, design: Design) -> list[float]:
    """The single directions (deg, in [0, 360)) inside the task's range where controllability is
    lost on zero width: point sectors of the design's tension map (a taut set that neither
    neighbouring sector has) whose spread is below ``min_spread``. Not violations by default
    (reported in ``result.json``); violations with ``strict_controllability``."""
    from ..model._zones import tension_map

    lo, span = math.degrees(float(sc.delta[0])), math.degrees(_span(sc))
    out = []
    for s in tension_map(design).sectors:
        p = s.start_deg % 360.0
        in_range = s.width_deg == 0 and (p - lo) % 360.0 <= span + 1e-9
        if in_range and float(_spread_jit(design, math.radians(p))) < sc.min_spread:
            out.append(round(p, 9))
    return sorted(set(out))


def _arc_slack(sc: Scenario, n: int, r: float) -> float:
    """Angle left over (rad) when n wires of radius r sit in the allowed arc with their gaps."""
    s_min = float(_min_angle(sc.wire_diameter + sc.min_wire_gap, r))
    if sc.forbidden_arc is None:
        return 2 * math.pi - n * s_min
    h = float(_min_angle(2 * (0.5 * sc.wire_diameter + sc.min_wire_gap), r)) / 2
    arc_len = 2 * math.pi - (sc.forbidden_arc[1] - sc.forbidden_arc[0])
    return arc_len - 2 * h - (n - 1) * s_min


def _r_range(sc: Scenario, n: int) -> tuple[float, float]:
    """Pitch-radius range for n wires: the scenario's bounds with the geometric limits, and with
    free angles the smallest radius at which the wires still fit their arc (the slack grows with r,
    so bisection finds it)."""
    r_lo, r_hi = sc.r_bounds(n)
    if sc.free_wire_angles and r_lo <= r_hi and _arc_slack(sc, n, r_lo) < 0:
        if _arc_slack(sc, n, r_hi) < 0:
            return r_hi, r_lo  # empty
        a, b = r_lo, r_hi
        for _ in range(60):
            m = 0.5 * (a + b)
            a, b = (m, b) if _arc_slack(sc, n, m) < 0 else (a, m)
        r_lo = b
    return r_lo, r_hi


def _bounds(sc: Scenario, n: int) -> _Bounds:
    r_lo, r_hi = _r_range(sc, n)
    arc0, arc_len = 0.0, 2 * math.pi
    if sc.forbidden_arc is not None:
        arc0 = sc.forbidden_arc[1]
        arc_len = 2 * math.pi - (sc.forbidden_arc[1] - sc.forbidden_arc[0])
    f = lambda x: jnp.asarray(x, float)
    return _Bounds(
        f(r_lo),
        f(r_hi),
        f(sc.wire_stiffness[0]),
        f(sc.wire_stiffness[1]),
        f(sc.wire_diameter + sc.min_wire_gap),
        f(0.5 * sc.wire_diameter + sc.min_wire_gap),
        f(arc0),
        f(arc_len),
    )


def _base(sc: Scenario, n: int) -> Design:
    return Design(n, sc.length, max(sc.pitch_radius[1], 1e-3), backbone_EI=sc.backbone_EI, preload=sc.preload)


# ---------------------------------------------------------------------------------------------
# The run
# ---------------------------------------------------------------------------------------------
@functools.partial(
    jax.jit, static_argnames=("n", "free", "arc", "steps", "with_defl"), compiler_options=fast_compile_options()
)
def _run_starts(z0, bounds: _Bounds, task: _Task, base: Design, lr, sharp0, *, n, free, arc, steps, with_defl):
    """Adam from every start at once (vmap over the leading axis of z0), continuation in sharpness.

    Returns per start: the best rank (exact objective, plus INFEASIBLE_RANK per violating pose); that
    iterate's design numbers (pitch radius, wire stiffness, wire angles (n,)), exact objective and
    pieces (:func:`_objective`); and the best-so-far rank after every step, (starts, steps).
    """
    opt = optax.adam(lr)

    def loss(z, sharp):
        d = _design(z, bounds, n, free, arc, base)
        smooth, exact, p = _objective(d, task, n, sharp, with_defl)
        # rank iterates by the exact objective, feasible ones first
        rank = exact + INFEASIBLE_RANK * (p["violations"] + p["statics_infeasible"])
        return smooth, (rank, ((d.pitch_radius, d.wire_stiffness, d.wire_angles), exact, p))

    def one_start(z):
        state = opt.init(z)

        def step(carry, i):
            z, state, best, best_out = carry
            sharp = sharp0 * 10.0 ** (i / jnp.maximum(steps - 1, 1))
            (_, (rank, out)), g = jax.value_and_grad(loss, has_aux=True)(z, sharp)
            # the first pass is always kept (so the start stands for itself, were nothing finite),
            # and a NaN rank is replaced by any later one
            improved = (rank < best) | (i == 0) | jnp.isnan(best)
            best = jnp.where(improved, rank, best)
            best_out = jax.tree_util.tree_map(lambda a, b: jnp.where(improved, a, b), out, best_out)
            upd, state = opt.update(g, state, z)
            z = optax.apply_updates(z, upd)
            z = {**z, "r": jnp.clip(z["r"], 0.0, 1.0), "k": jnp.clip(z["k"], 0.0, 1.0)}
            return (z, state, best, best_out), jnp.where(jnp.isnan(best), jnp.inf, best)

        # one pass more than the steps: it ranks the last step's result (its update goes unused), and
        # the best iterate's pieces ride along, so the program holds one copy of the objective and
        # nothing else compiles it (a copy to rank the last step, or the objective's own program for
        # the best's pieces, would each cost another trace and compile per wire count)
        out0 = jax.eval_shape(lambda z: loss(z, sharp0)[1][1], z)
        init = (z, state, jnp.asarray(jnp.inf), jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), out0))
        (_, _, best, best_out), hist = jax.lax.scan(step, init, jnp.arange(steps + 1))
        return jnp.where(jnp.isnan(best), jnp.inf, best), best_out, hist[1:]

    return jax.vmap(one_start)(z0)


@functools.partial(jax.jit, static_argnames=("S", "n", "n_gaps"))
def _initial(key, S: int, n: int, n_gaps: int) -> dict:
    """``S`` starts' unconstrained variables (one program: run op by op, each operation would compile alone)."""
    k1, k2, k3, k4 = jax.random.split(key, 4)
    z = {
        "r": jax.random.uniform(k1, (S,)),
        "k": jax.random.uniform(k2, (S,)),
        "a0": jax.random.uniform(k3, (S,), minval=0.0, maxval=2 * jnp.pi / n),
        "gaps": 0.5 * jax.random.normal(k4, (S, n_gaps)),
    }
    # start 0 is the "obvious" design: mid-range values, evenly spread wires
    z["r"] = z["r"].at[0].set(0.5)
    z["k"] = z["k"].at[0].set(0.5)
    z["gaps"] = z["gaps"].at[0].set(0.0)
    return z


def _result_row(sc: Scenario, n, d: Design, exact, pieces) -> dict[str, Any]:
    """One wire count's result. With a deflection weight of 0 the statics are never computed: their
    figures are NaN (``null`` in ``result.json``), not 0, and feasibility is controllability alone."""
    statics = sc.w_deflection > 0
    infeasible = int(pieces["statics_infeasible"]) if statics else math.nan
    return {
        "n_wires": n,
        "pitch_radius_mm": float(d.pitch_radius),
        "wire_stiffness_N_per_mm": float(d.wire_stiffness),
        "wire_angles_deg": [float(a) for a in np.mod(np.degrees(np.asarray(d.wire_angles)), 360.0)],
        "objective": float(exact),
        "worst_position_uncertainty_mm": float(pieces["worst_dp"]),
        "worst_deflection_mm": float(pieces["worst_defl"]) if statics else math.nan,
        "min_spread": float(pieces["min_spread"]),
        "spread_violations": int(pieces["violations"]),
        "zero_width_directions_deg": zero_width_directions(sc, d),
        "statics_infeasible_poses": infeasible,
        "feasible": bool(int(pieces["violations"]) == 0 and (not statics or infeasible == 0)),
    }


def optimize(sc: Scenario, progress: bool = True) -> dict[str, Any]:
    """Optimise every candidate wire count; return the ``result.json`` dictionary.

    ``history`` (per wire count: the best exact objective after each step, best start) is included
    for the convergence plot.
    """
    from tqdm.auto import tqdm

    t0 = time.perf_counter()
    task = _task(sc)
    key = jax.random.PRNGKey(sc.seed)
    rows, hist, evaluations = [], {}, 0
    counts = tqdm(sc.n_wires, desc="wire counts", disable=not progress, leave=False)
    for n in counts:
        r_lo, r_hi = _r_range(sc, n)
        if r_lo > r_hi:
            rows.append(
                {
                    "n_wires": n,
                    "feasible": False,
                    "reason": "the geometric constraints leave no room for this many wires",
                }
            )
            continue
        key, sub = jax.random.split(key)
        bounds, base = _bounds(sc, n), _base(sc, n)
        free, arc = sc.free_wire_angles, sc.forbidden_arc is not None
        z0 = _initial(sub, S=sc.starts, n=n, n_gaps=n + 1 if arc else n)
        best, out, h = _run_starts(
            z0,
            bounds,
            task,
            base,
            jnp.asarray(sc.learning_rate),
            jnp.asarray(sc.sharpness),
            n=n,
            free=free,
            arc=arc,
            steps=sc.steps,
            with_defl=sc.w_deflection > 0,
        )
        evaluations += sc.starts * (sc.steps + 1)
        i = int(np.argmin(np.asarray(best)))
        (r, k, angles), exact, pieces = jax.tree_util.tree_map(lambda a: np.asarray(a[i]), out)  # noqa: B023  (called at once)
        d = base.replace(pitch_radius=float(r), wire_stiffness=float(k), wire_angles=angles)
        rows.append(_result_row(sc, n, d, exact, pieces))
        hist[str(n)] = np.asarray(h[i]).tolist()
    feasible = [r for r in rows if r.get("feasible")]
    best_row = min(feasible, key=lambda r: r["objective"]) if feasible else None
    return {
        "best": best_row,
        "strict_controllability": sc.strict_controllability,
        "per_wire_count": rows,
        "seconds": time.perf_counter() - t0,
        "evaluations": evaluations,
        "history": hist,
    }


def evaluate_design(sc: Scenario, design: Design) -> dict[str, Any]:
    """The exact objective and its pieces for a given design under a scenario (e.g. to check a
    hand-made design, or the evenly spaced one, against the constraints)."""
    _, exact, pieces = _objective_jit(design, _task(sc), design.n_wires, 1.0, sc.w_deflection > 0)
    return _result_row(sc, design.n_wires, design, exact, pieces)
