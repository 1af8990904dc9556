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

**Several segments** (a scenario with ``segments``): every combination of the segments' wire counts
is a robot (``_layout``: interleaved wires, each proximal disk's hole circle), optimised by the same
loop (:func:`_run_starts` with a :class:`_Chain` problem) over each segment's pitch radius, wire
stiffness and preload, for ``w_p * max dp_max_reduced + w_n * N`` over the task's configurations,
and ``w_d * max deflection`` under the task's tip load (pull-only tensions over the chain), with
controllability checked at each configuration (:func:`chain_spread`).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._numerics import compact_programs, singular_values
from .._xla import fast_compile_options, shapes_key, stored_program
from ..model._design import Design
from ..model._robot import Robot, routing_matrix
from ..model._zones import tension_mask
from ._layout import chain, hole_gaps, interleaved_angles, per_segment, with_numbers
from ._scenario import Scenario, wires_label

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
    return dp, *_reduced_deflection(compliance_pose(design, theta_L, delta, task.load))


def _reduced_deflection(c: dict):
    """(reduced deflection (mm), statics feasible) of a compliance result: 0 where the wires cannot hold
    the load pulling only, or the deflection is not finite."""
    ok = c["feasible"] & jnp.isfinite(c["deflection_mm_reduced"])
    return jnp.where(ok, c["deflection_mm_reduced"], 0.0), ok  # double-where: no NaN in gradients


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
    results = [_shortfall(spr, task.min_spread) for spr in (_range_spread(design, task), _sector_spread(design, task))]
    strict = task.strict | (task.delta_span <= ZERO_WIDTH_RAD)
    return tuple(jnp.where(strict, a, b) for a, b in zip(*results))


def _shortfall(spr, min_spread):
    """``(penalty, violations, smallest)`` of the spreads ``spr`` checked: the mean squared shortfall
    below ``min_spread``, how many fall below it, and the smallest (``inf`` entries: not checked)."""
    viol = jnp.maximum(min_spread - spr, 0.0)  # 0 for unchecked entries (inf)
    return jnp.mean(viol**2), jnp.sum(spr < min_spread), jnp.min(spr)


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


def _objective(design, task, n: int, sharpness, with_defl: bool = True):
    """(smooth objective for gradients, exact objective, exact pieces) of a :class:`Design` over its
    task grid (:class:`_Task`) or of a :class:`Robot` over its configurations (:class:`_ChainTask`);
    ``n`` the wire count the wire term charges.

    Traced in the compact forms (:func:`~tension_zones._numerics.compact_programs`): the optimiser's
    program takes far longer to compile than to run, and the compact forms compile faster.
    """
    terms = _grid_terms if isinstance(design, Design) else _sample_terms
    with compact_programs():
        dp, defl, ok, (shortfall, violations, min_spread) = terms(design, task, with_defl)
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
# Several segments: each segment's hole circle, wire stiffness and preload over configurations
# ---------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _ChainBounds:
    """Each segment's box, (S,) each: pitch radius, wire stiffness, preload (a pytree of arrays)."""

    r_lo: jax.Array
    r_hi: jax.Array
    k_lo: jax.Array
    k_hi: jax.Array
    p_lo: jax.Array
    p_hi: jax.Array


@dataclasses.dataclass(frozen=True)
class _ChainTask:
    """A task of several segments as arrays (a pytree: new values of the same shapes never recompile)."""

    configs: jax.Array  # (M, S, 2) rad
    dq: jax.Array
    load: jax.Array  # (3,) N, base frame
    w_position: jax.Array
    w_deflection: jax.Array
    w_wires: jax.Array
    min_spread: jax.Array


for _cls in (_ChainBounds, _ChainTask):
    jax.tree_util.register_dataclass(_cls, data_fields=[f.name for f in dataclasses.fields(_cls)], meta_fields=[])


def _robot(z, b: _ChainBounds, base: Robot) -> Robot:
    """The robot of box variables ``z["r"], z["k"], z["p"]`` (S,) in [0, 1] (a fixed value's box is one
    point)."""
    lerp = lambda key, lo, hi: lo + (hi - lo) * z[key]
    return with_numbers(
        base,
        pitch_radius=lerp("r", b.r_lo, b.r_hi),
        wire_stiffness=lerp("k", b.k_lo, b.k_hi),
        preload=lerp("p", b.p_lo, b.p_hi),
    )


def chain_spread(robot: Robot, B):
    """Smallest singular value of the taut wires' directions at a configuration ``B`` (S, 2): the rows
    ``[cos a_kj, sin a_kj]`` of each segment ``j`` wire ``k`` crosses (``J_qB`` with unit radii) of the
    wires in tension; 0 unless they span all ``2S`` bending directions. A one-segment robot gives
    :func:`spread` (the same rows turned by ``delta``)."""
    m = robot.tension_mask(B)
    U = routing_matrix(robot.route_angles, jnp.ones_like(robot.route_radii), robot.crosses)
    return singular_values(U * m[:, None])[-1]


def _config_terms(robot: Robot, B, task: _ChainTask, with_defl: bool = True):
    """(dp_max (mm), reduced deflection (mm), statics feasible) at one configuration ``B`` (S, 2), as
    :func:`_pose_terms` for a segment: the reduced bound of the wires in tension (``config_measures``)
    and the reduced deflection under the task's tip load (``model.config_compliance``, pull-only
    tensions over the whole chain)."""
    from ..analysis._chain import config_measures
    from ..model._chain_statics import config_compliance

    dp = config_measures(robot, B, task.dq, robot.tension_mask(B))["dp_max"]
    if not with_defl:  # static: a zero deflection weight skips the statics entirely
        return dp, jnp.zeros_like(dp), jnp.ones_like(dp, dtype=bool)
    return dp, *_reduced_deflection(config_compliance(robot, B, task.load))


def _sample_terms(robot: Robot, task: _ChainTask, with_defl: bool = True):
    """Per-configuration terms over the task's configurations, each (M,), and the controllability
    check at each configuration (:func:`chain_spread`)."""
    dp, defl, ok = jax.vmap(lambda B: _config_terms(robot, B, task, with_defl))(task.configs)
    spr = jax.vmap(lambda B: chain_spread(robot, B))(task.configs)
    return dp, defl, ok, _shortfall(spr, task.min_spread)


def _chain_task(sc: Scenario) -> _ChainTask:
    f = lambda x: jnp.asarray(x, float)
    return _ChainTask(
        f(sc.configs), f(sc.dq), f(sc.load), f(sc.w_position), f(sc.w_deflection), f(sc.w_wires), f(sc.min_spread)
    )


def _chain_bounds(sc: Scenario, counts) -> _ChainBounds | None:
    """Each segment's box for ``counts`` wires per segment (its pitch radius within its outer diameter
    and keeping its disk's holes apart, :func:`hole_gaps`); ``None`` where one has no room."""
    gaps = hole_gaps(interleaved_angles(counts))
    r = [seg.r_bounds(n, gap) for seg, n, gap in zip(sc.segments, counts, gaps)]
    if any(lo > hi for lo, hi in r):
        return None
    p = [seg.preload_range or (seg.preload, seg.preload) for seg in sc.segments]
    f = lambda x: jnp.asarray(x, float)
    cols = [*zip(*r), *zip(*(seg.wire_stiffness for seg in sc.segments)), *zip(*p)]
    return _ChainBounds(*(f(c) for c in cols))


def _base_robot(sc: Scenario, counts) -> Robot:
    """The robot of ``counts`` wires per segment with the scenario's fixed numbers (its variables are set
    by :func:`_robot`)."""
    segs = sc.segments
    return chain(
        counts,
        [s.length for s in segs],
        [max(s.pitch_radius[1], 1e-3) for s in segs],
        backbone_EI=[s.backbone_EI for s in segs],
        preload=[s.preload for s in segs],
    )


# ---------------------------------------------------------------------------------------------
# The problems: what the box variables z are, the subject they make and what is reported of it
# ---------------------------------------------------------------------------------------------
#: The box variables, scaled to [0, 1] and projected after every step.
BOX = ("r", "k", "p")


@dataclasses.dataclass(frozen=True)
class _Segment:
    """One segment of ``n`` wires (static: one compiled program each): its pitch radius, wire
    stiffness and, with ``free``, its wire angles (inside the allowed arc with ``arc``)."""

    n: int
    free: bool
    arc: bool
    with_defl: bool

    @property
    def wires(self) -> int:
        return self.n

    def subject(self, z, b: _Bounds, base: Design) -> Design:
        return _design(z, b, self.n, self.free, self.arc, base)

    @staticmethod
    def numbers(d: Design):
        """The design's numbers a result reports: pitch radius, wire stiffness, wire angles (n,)."""
        return d.pitch_radius, d.wire_stiffness, d.wire_angles


@dataclasses.dataclass(frozen=True)
class _Chain:
    """A robot of ``counts`` wires per segment (static: one compiled program each): each segment's
    pitch radius, wire stiffness and preload (a variable where its range is not one value)."""

    counts: tuple[int, ...]
    with_defl: bool

    @property
    def wires(self) -> int:
        return sum(self.counts)

    @staticmethod
    def subject(z, b: _ChainBounds, base: Robot) -> Robot:
        return _robot(z, b, base)

    @staticmethod
    def numbers(robot: Robot):
        """The robot's numbers a result reports: per segment (S,) pitch radius, wire stiffness, preload."""
        return tuple(per_segment(robot, f) for f in ("pitch_radius", "wire_stiffness", "preload"))


# ---------------------------------------------------------------------------------------------
# The run
# ---------------------------------------------------------------------------------------------
def _run_starts(z0, bounds, task, base, lr, sharp0, *, problem, steps):
    """Adam from every start at once (vmap over the leading axis of z0), continuation in sharpness.

    ``problem`` (static, :class:`_Segment` or :class:`_Chain`) makes the subject of ``z`` and says
    which of its numbers a result reports. Returns per start: the best rank (exact objective, plus
    INFEASIBLE_RANK per violating pose); that iterate's numbers, exact objective and pieces
    (:func:`_objective`); and the best-so-far rank after every step, (starts, steps).
    """
    opt = optax.adam(lr)

    def loss(z, sharp):
        d = problem.subject(z, bounds, base)
        smooth, exact, p = _objective(d, task, problem.wires, sharp, problem.with_defl)
        # rank iterates by the exact objective, feasible ones first
        rank = exact + INFEASIBLE_RANK * (p["violations"] + p["statics_infeasible"])
        return smooth, (rank, (problem.numbers(d), exact, p))

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
            z = {k: jnp.clip(v, 0.0, 1.0) if k in BOX else v for k, v in z.items()}
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


#: The optimiser's programs in this process, by problem, step count and argument shapes.
_RUNS: dict = {}


def _run(problem, steps: int, *args):
    """:func:`_run_starts` for ``problem`` and ``steps`` (static) on ``args``, compiled once per
    problem, step count and argument shapes, and kept on disk before tracing
    (``_xla.stored_program``): a later process (the command run again, a new notebook kernel) skips
    the trace and lowering, which take about as long as the compile for these programs."""
    leaves, tree = jax.tree_util.tree_flatten(args)
    key = (problem, steps, *shapes_key(args))
    fn = _RUNS.get(key)
    if fn is None:

        def flat(*leaves):  # (an exported program's arguments are plain arrays: no dataclass to register)
            return _run_starts(*jax.tree_util.tree_unflatten(tree, leaves), problem=problem, steps=steps)

        opts = fast_compile_options()
        fn = jax.jit(flat, compiler_options=opts)
        fn = _RUNS[key] = stored_program(fn, tuple(leaves), f"optimiser|{problem!r}|{steps}|{tree}", opts)
    return fn(*leaves)


def programs() -> int:
    """How many programs the optimiser has traced in this process (a test counts them): one per
    problem, step count and argument shapes; new values never add one."""
    return sum(fn._cache_size() for fn in _RUNS.values())


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


@functools.partial(jax.jit, static_argnames=("starts", "segments"))
def _initial_box(key, starts: int, segments: int) -> dict:
    """``starts`` starts' box variables of a robot, each (starts, segments); start 0 mid-range."""
    return {
        k: jax.random.uniform(sub, (starts, segments)).at[0].set(0.5) for k, sub in zip(BOX, jax.random.split(key, 3))
    }


def _figures(sc: Scenario, exact, pieces, zero_width=None) -> dict[str, Any]:
    """A result's objective, its pieces and feasibility (``zero_width``: one segment's single
    directions, :func:`zero_width_directions`). With a deflection weight of 0 the statics are never
    computed: their figures are NaN (``null`` in ``result.json``), not 0, and feasibility is
    controllability alone."""
    statics = sc.w_deflection > 0
    infeasible = int(pieces["statics_infeasible"]) if statics else math.nan
    out = {
        "objective": float(exact),
        "worst_position_uncertainty_mm": float(pieces["worst_dp"]),
        "worst_deflection_mm": float(pieces["worst_defl"]) if statics else math.nan,
        "min_spread": float(pieces["min_spread"]),
        "spread_violations": int(pieces["violations"]),
    }
    if zero_width is not None:
        out["zero_width_directions_deg"] = zero_width
    out["statics_infeasible_poses"] = infeasible
    out["feasible"] = bool(int(pieces["violations"]) == 0 and (not statics or infeasible == 0))
    return out


def _result_row(sc: Scenario, n, d: Design, exact, pieces) -> dict[str, Any]:
    """One wire count's result."""
    return {
        "n_wires": n,
        "pitch_radius_mm": float(d.pitch_radius),
        "wire_stiffness_N_per_mm": float(d.wire_stiffness),
        "wire_angles_deg": [float(a) for a in np.mod(np.degrees(np.asarray(d.wire_angles)), 360.0)],
        **_figures(sc, exact, pieces, zero_width_directions(sc, d)),
    }


def _chain_row(sc: Scenario, robot: Robot, exact, pieces) -> dict[str, Any]:
    """One combination of wire counts' result: per segment (proximal first) its numbers, the figures,
    and the robot as a design-file dict (``design``, read by :meth:`Robot.from_dict`)."""
    per = lambda f: np.asarray(per_segment(robot, f)).tolist()
    return {
        "n_wires": list(robot.n_wires_per_segment),
        "pitch_radius_mm": per("pitch_radius"),
        "wire_stiffness_N_per_mm": per("wire_stiffness"),
        "preload_N": per("preload"),
        "wire_angles_deg": [np.mod(s.wire_angles_deg, 360.0).tolist() for s in robot.segments],
        **_figures(sc, exact, pieces),
        "design": robot.to_dict(),
    }


def _best_start(best, out):
    """The best start's numbers, exact objective and pieces (NumPy), and its index."""
    i = int(np.argmin(np.asarray(best)))
    return jax.tree_util.tree_map(lambda a: np.asarray(a[i]), out), i


def _run_segment(sc: Scenario, n: int, key):
    """One wire count's search: its result row and best-so-far history (best start)."""
    bounds, base = _bounds(sc, n), _base(sc, n)
    free, arc = sc.free_wire_angles, sc.forbidden_arc is not None
    z0 = _initial(key, S=sc.starts, n=n, n_gaps=n + 1 if arc else n)
    problem = _Segment(n, free, arc, sc.w_deflection > 0)
    lr, sharp = jnp.asarray(sc.learning_rate), jnp.asarray(sc.sharpness)
    best, out, h = _run(problem, sc.steps, z0, bounds, _task(sc), base, lr, sharp)
    ((r, k, angles), exact, pieces), i = _best_start(best, out)
    d = base.replace(pitch_radius=float(r), wire_stiffness=float(k), wire_angles=angles)
    return _result_row(sc, n, d, exact, pieces), np.asarray(h[i]).tolist()


def _run_chain(sc: Scenario, counts: tuple[int, ...], key):
    """One combination of wire counts' search (several segments): its result row and history."""
    base = _base_robot(sc, counts)
    z0 = _initial_box(key, starts=sc.starts, segments=len(counts))
    problem = _Chain(counts, sc.w_deflection > 0)
    lr, sharp = jnp.asarray(sc.learning_rate), jnp.asarray(sc.sharpness)
    best, out, h = _run(problem, sc.steps, z0, _chain_bounds(sc, counts), _chain_task(sc), base, lr, sharp)
    ((r, k, p), exact, pieces), i = _best_start(best, out)
    robot = with_numbers(base, pitch_radius=r, wire_stiffness=k, preload=p)
    return _chain_row(sc, robot, exact, pieces), np.asarray(h[i]).tolist()


def structures(sc: Scenario) -> list:
    """What the optimiser searches one after the other: the wire counts of one segment, or every
    combination of the segments' counts (tuples, proximal first)."""
    if not sc.segments:
        return list(sc.n_wires)
    return list(itertools.product(*(seg.n_wires for seg in sc.segments)))


def _fits(sc: Scenario, n) -> bool:
    if sc.segments:
        return _chain_bounds(sc, n) is not None
    r_lo, r_hi = _r_range(sc, n)
    return r_lo <= r_hi


def optimize(sc: Scenario, progress: bool = True, start: Design | Robot | None = None) -> dict[str, Any]:
    """Optimise every candidate wire count (several segments: every combination); return the
    ``result.json`` dictionary.

    ``history`` (per wire count: the best exact objective after each step, best start) is included
    for the convergence plot. ``start``: the design the search starts from (``optimize --design``, a
    calibrated robot, with the scenario of :func:`~._scenario.for_robot`), evaluated as it is under
    the scenario (its own layout and routing) into ``start``, to set the best against.
    """
    from tqdm.auto import tqdm

    t0 = time.perf_counter()
    key = jax.random.PRNGKey(sc.seed)
    rows, hist, evaluations = [], {}, 0
    for n in tqdm(structures(sc), desc="wire counts", disable=not progress, leave=False):
        if not _fits(sc, n):
            reason = "the geometric constraints leave no room for this many wires"
            rows.append({"n_wires": n if isinstance(n, int) else list(n), "feasible": False, "reason": reason})
            continue
        key, sub = jax.random.split(key)
        row, hist[wires_label(n)] = (_run_chain if sc.segments else _run_segment)(sc, n, sub)
        rows.append(row)
        evaluations += sc.starts * (sc.steps + 1)
    feasible = [r for r in rows if r.get("feasible")]
    best_row = min(feasible, key=lambda r: r["objective"]) if feasible else None
    out = {
        "best": best_row,
        "strict_controllability": sc.strict_controllability,
        "per_wire_count": rows,
        "seconds": time.perf_counter() - t0,
        "evaluations": evaluations,
        "history": hist,
    }
    if start is not None:
        if isinstance(start, Robot) and start.n_segments == 1:
            start = start.segments[0]
        out["start"] = evaluate_design(sc, start)
    return {"segments": len(sc.segments), **out} if sc.segments else out


def evaluate_design(sc: Scenario, design: Design | Robot) -> dict[str, Any]:
    """The exact objective and its pieces for a given design (a :class:`Robot` under a scenario of
    several segments) under a scenario (e.g. to check a hand-made design, or the evenly spaced one,
    against the constraints)."""
    if isinstance(design, Robot):
        if design.n_segments != len(sc.segments):
            raise ValueError(f"the robot has {design.n_segments} segment(s), the scenario {len(sc.segments) or 1}")
        _, exact, pieces = _objective_jit(design, _chain_task(sc), design.n_wires, 1.0, sc.w_deflection > 0)
        return _chain_row(sc, design, exact, pieces)
    if sc.segments:
        raise ValueError(f"the scenario has {len(sc.segments)} segments: evaluate a Robot")
    _, exact, pieces = _objective_jit(design, _task(sc), design.n_wires, 1.0, sc.w_deflection > 0)
    return _result_row(sc, design.n_wires, design, exact, pieces)
