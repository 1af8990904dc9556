"""Identify the paper's unreported segment (L, r, backbone EI) from its Tables 1-2 (paper Sec. 6.2).

The paper gives the wire stiffness, the load ``w = [5 N, 0, 0, 0, 0, 0]`` and the sweep grid, and
reports the workspace means (and SDs) of the reduced position and angular deflections for three
and four wires at ``k_w`` = 55, 75, 105 N/mm: twelve means. ``L``, ``r`` and ``EI`` are identified by
Levenberg-Marquardt on the twelve relative errors, differentiating through the whole
statics pipeline (tension QP, taut set, stiffness, compliance) in log-parameters.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .._lsq import levenberg_marquardt
from .._xla import fast_compile_options
from ..model._design import Design
from ..model._kinematics import over_grid
from ..model._statics import PAPER_DELTA_DEG, PAPER_THETA_L_DEG, PAPER_WRENCH, compliance_pose

#: Paper Tables 1-2: {n_wires: {k_w: (pos mean mm, pos SD mm, ang mean deg, ang SD deg)}}
#: (reduced Jacobian, no preload; Table 1 is k_w = 75 N/mm).
PAPER_TABLE = {
    3: {
        55: (4.52, 0.150, 33.8, 0.96),
        75: (3.052, 0.099, 22.81, 0.621),
        105: (2.04, 0.065, 15.3, 0.41),
    },
    4: {
        55: (2.20, 0.066, 16.5, 0.41),
        75: (1.558, 0.047, 11.65, 0.287),
        105: (1.08, 0.032, 8.06, 0.20),
    },
}
#: The paper's headline: the traditional Jacobian underestimates the three-wire deflection by 206 %.
PAPER_REDUCED_OVER_TRADITIONAL_3 = 3.06
#: Order of the twelve fitted means: (n, k_w, "mm" | "deg").
FIT_KEYS = tuple((n, k, q) for n in (3, 4) for k in (55, 75, 105) for q in ("mm", "deg"))


def initial_guess():
    """Start of the fit from the tables by the small-bending limit (straight segment, load along x).

    There ``|dtheta| ~ (2/L) |dp|``, so ``L0 = 2 pos/ang`` (Table 1, three wires); a four-wire
    segment resists the load with ``k_w r^2`` (two adjacent taut wires, or one aligned with x) and
    ``|dp| ~ L^2 f / (4 k_w r^2)``, so ``r0 = L0 sqrt(f / (4 k_w pos4))``; ``EI0 = 0.5 L0^2`` N mm^2
    keeps every pose of the grid stable (the load's geometric stiffness is about ``-f L phi / 12``).
    """
    pos3, _, ang3, _ = PAPER_TABLE[3][75]
    L0 = 2.0 * pos3 / np.radians(ang3)
    r0 = L0 * np.sqrt(PAPER_WRENCH[0] / (4.0 * 75.0 * PAPER_TABLE[4][75][0]))
    return (float(L0), float(r0), float(0.5 * L0**2))


def paper_means() -> np.ndarray:
    """The twelve target means in :data:`FIT_KEYS` order."""
    return np.array([PAPER_TABLE[n][k][0 if q == "mm" else 2] for n, k, q in FIT_KEYS])


def _grid():
    return jnp.radians(jnp.asarray(PAPER_THETA_L_DEG)), jnp.radians(jnp.asarray(PAPER_DELTA_DEG))


def workspace_stats(design: Design, mode: str = "reduced", wrench=PAPER_WRENCH):
    """Workspace mean and SD of ``|dp|`` (mm) and ``|dtheta|`` (deg) on the paper's grid; traceable.

    Returns ``(4,)``: pos mean, pos SD, ang mean, ang SD (SD with ``N - 1``, as MATLAB's ``std``).
    """
    th, de = _grid()
    out = over_grid(compliance_pose)(design, th, de, jnp.asarray(wrench, float))
    mm, deg = out[f"deflection_mm_{mode}"], out[f"deflection_deg_{mode}"]
    return jnp.stack([jnp.mean(mm), jnp.std(mm, ddof=1), jnp.mean(deg), jnp.std(deg, ddof=1)])


def model_means(log_params):
    """The twelve model means (``FIT_KEYS`` order) for ``log([L, r, EI])``; differentiable."""
    L, r, EI = jnp.exp(log_params)
    ks = jnp.asarray([55.0, 75.0, 105.0])
    out = [
        jax.vmap(lambda k: workspace_stats(Design(n, L, r, wire_stiffness=k, backbone_EI=EI)))(ks)  # noqa: B023
        for n in (3, 4)  # n fixes array shapes: one trace per wire count
    ]
    return jnp.stack(out)[:, :, (0, 2)].reshape(-1)  # (n, k, [mm, deg]) = FIT_KEYS order


def _residuals(log_params, target):
    return model_means(log_params) / target - 1.0


@partial(jax.jit, compiler_options=fast_compile_options())
def _fit(init, target, maxiter):
    """The package's least-squares solver (:func:`tension_zones._lsq.levenberg_marquardt`) on the twelve
    relative errors, in log-parameters; a step whose residuals are not finite (some workspace pose
    loses stability and its deflection is flagged NaN) is rejected like any step that does not descend."""
    theta, _, iterations, r, _ = levenberg_marquardt(lambda p: _residuals(p, target), init, max_iter=maxiter, tol=1e-14)
    return theta, iterations, r[:, 0]


def identify(initial=None, maxiter: int = 50):
    """Identify ``(L, r, EI)`` from the twelve table means (Levenberg-Marquardt in log-parameters).

    Returns a dict: ``length_mm``, ``pitch_radius_mm``, ``backbone_EI_Nmm2``, ``relative_errors``
    (12,), ``mean_relative_error``, ``model_means`` (12,), ``iterations`` (accepted steps).
    """
    target = jnp.asarray(paper_means())
    if initial is None:  # the small-bending guess, with three backbone stiffnesses
        L0, r0, EI0 = initial_guess()
        starts = [(L0, r0, EI0 * s) for s in (0.7, 1.0, 2.0)]
    else:
        starts = [initial]
    best = None
    for guess in starts:
        start = np.asarray(guess, dtype=float)
        if start.shape != (3,) or not np.all(np.isfinite(start)) or np.any(start <= 0):
            raise ValueError(f"initial (L, r, EI) must be three positive numbers, got {start.tolist()}")
        init = np.log(start)
        p, its, r = _fit(jnp.asarray(init), target, maxiter)
        p, its, r = np.asarray(p), int(its), np.asarray(r)
        if np.all(np.isfinite(r)) and (best is None or r @ r < best[2] @ best[2]):
            best = (p, its, r)
    if best is None:
        raise ValueError("the identification found no parameter set with a stable workspace")
    p, its, err = best  # the residuals at the result, from the fit's program (an eager evaluation
    # of the vmapped workspace statistics would dispatch, and compile, some 300 single operations)
    L, r, EI = (float(x) for x in np.exp(np.asarray(p)))
    return {
        "length_mm": L,
        "pitch_radius_mm": r,
        "backbone_EI_Nmm2": EI,
        "relative_errors": err,
        "mean_relative_error": float(np.mean(np.abs(err))),
        "model_means": np.asarray(target * (1.0 + err)),
        "iterations": its,
    }
