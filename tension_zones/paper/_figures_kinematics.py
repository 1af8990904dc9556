"""Paper Sec. 6.1: Figs. 9-12 and the ``summary.json`` numbers of ``tension-zones reproduce``.

The kinematic measures and the joint-uncertainty bounds scale simply with the design (KCI is
scale-free; ``sigma_v``, ``dp_max`` scale as ``L/r``; ``sigma_w``, ``dw_max`` as ``1/r``), so every
ratio the paper quotes is independent of ``L`` and ``r``. The paper gives neither; the figures use
:data:`LENGTH` = 20 mm and :data:`PITCH_RADIUS` = 2 mm (absolute values scale as stated above).

Definitions of the summary numbers (all on the paper's grid, theta_L 0..85 deg step 5, delta 0..360
deg step 2.5, reduced Jacobians unless "full" is said, dq = 0.4 mm unless a dq sweep is said):

* ``reduced_over_full_max[n]``: max over the grid of ``dp_max_reduced / dp_max_full`` for n wires
  (how much the traditional Jacobian underestimates the position uncertainty, at worst).
* ``three_over_four_max[q]``: max over the grid of ``B3 / B4``, the bounds of the two designs at
  the same pose (``B`` = ``dp_max`` for q = position, ``dw_max`` for orientation), leaving out the zero-width directions where the
  four-wire design has a single taut wire (delta = k 90 deg, tension_zones/MODEL.md boundary rule); the
  unrestricted value is reported as ``three_over_four_max_all``.
* ``sensitivity_three_over_four[q]``: ratio of the slopes (least squares over dq = 0.2..1.0 mm) of
  the workspace-maximal bound ``max_grid B(dq)``, three wires over four.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Documented defaults (the paper gives no dimensions; its ratios do not depend on them).
LENGTH = 20.0
PITCH_RADIUS = 2.0
DQ = 0.4
DQ_SWEEP = (0.2, 0.4, 0.6, 0.8, 1.0)
QUANTITIES = {"position": ("dp_max", "mm"), "orientation": ("dw_max", "rad")}


def paper_sweeps(dq_values=DQ_SWEEP, length=LENGTH, pitch_radius=PITCH_RADIUS, quiet=True):
    """Sweep the three- and four-wire designs over the paper grid for every ``dq``.

    Returns ``(theta_deg, delta_deg, results)`` with ``results[(n, dq)]`` the dict of
    :func:`tension_zones.analysis.pose_metrics` arrays, shape (18, 145).
    """
    from ..analysis._metrics import pose_metrics
    from ..analysis._sweep import grid_deg, sweep_grid
    from ..model._design import Design

    theta_deg, delta_deg = grid_deg(85.0, 5.0), grid_deg(360.0, 2.5)
    results = {}
    for n in (3, 4):
        d = Design(n, length, pitch_radius)
        for dq in dq_values:
            results[(n, dq)] = sweep_grid(
                pose_metrics, d, np.radians(theta_deg), np.radians(delta_deg), dq, quiet=quiet
            )
    return theta_deg, delta_deg, results


def _frac(a, b):
    """Fraction of poses with a > b (relative tolerance 1e-12 for ties)."""
    return float(np.mean(a > b + 1e-12 * np.maximum(np.abs(a), np.abs(b))))


def uncertainty_summary(results, dq=DQ, dq_values=DQ_SWEEP) -> dict:
    r3, r4 = results[(3, dq)], results[(4, dq)]
    two4 = r4["n_taut"] >= 2
    both_two = (r3["n_taut"] == 2) & two4
    out = {
        "dq_mm": dq,
        "length_mm": LENGTH,
        "pitch_radius_mm": PITCH_RADIUS,
        "reduced_over_full_max": {},
        "reduced_over_full_max_orientation": {},
        "three_over_four_max": {},
        "three_over_four_max_all": {},
        "three_over_four_range_two_taut_each": {},
        "three_over_four_range_all": {},
        "three_over_four_ratio_of_maxima": {},
        "sensitivity_three_over_four": {},
        "sensitivity_slope": {"3": {}, "4": {}},
    }
    for n, r in ((3, r3), (4, r4)):
        out["reduced_over_full_max"][str(n)] = float(np.max(r["dp_max_reduced"] / r["dp_max_full"]))
        out["reduced_over_full_max_orientation"][str(n)] = float(np.max(r["dw_max_reduced"] / r["dw_max_full"]))
    for q, (key, _) in QUANTITIES.items():
        ratio = r3[f"{key}_reduced"] / r4[f"{key}_reduced"]
        out["three_over_four_max"][q] = float(ratio[two4].max())
        out["three_over_four_max_all"][q] = float(ratio.max())
        out["three_over_four_range_two_taut_each"][q] = [float(ratio[both_two].min()), float(ratio[both_two].max())]
        out["three_over_four_range_all"][q] = [float(ratio.min()), float(ratio.max())]
        out["three_over_four_ratio_of_maxima"][q] = float(r3[f"{key}_reduced"].max() / r4[f"{key}_reduced"].max())
        slopes = {}
        for n in (3, 4):
            worst = [results[(n, x)][f"{key}_reduced"].max() for x in dq_values]
            slopes[n] = float(np.polyfit(dq_values, worst, 1)[0])
            out["sensitivity_slope"][str(n)][q] = slopes[n]
        out["sensitivity_three_over_four"][q] = slopes[3] / slopes[4]
    return out


def kinematics_summary(results, dq=DQ) -> dict:
    """Paper conclusions (1)-(4) on the grid: fractions of poses where each statement holds."""
    r3, r4 = results[(3, dq)], results[(4, dq)]
    out = {}
    for part in ("v", "w"):
        s = {
            "kci_full_ge_reduced_3": float(np.mean(r3[f"kci_{part}_full"] >= r3[f"kci_{part}_reduced"] - 1e-12)),
            "kci_reduced_4_gt_3": _frac(r4[f"kci_{part}_reduced"], r3[f"kci_{part}_reduced"]),
            "kci_reduced_max": {
                "3": float(r3[f"kci_{part}_reduced"].max()),
                "4": float(r4[f"kci_{part}_reduced"].max()),
            },
            "kci_reduced_mean": {
                "3": float(r3[f"kci_{part}_reduced"].mean()),
                "4": float(r4[f"kci_{part}_reduced"].mean()),
            },
        }
        for reading, name in (("sigma_2", "sigma_min"), ("nonzero", "sigma_min_nz")):
            s[f"reduced_gt_full_{reading}"] = {
                str(n): _frac(r[f"{name}_{part}_reduced"], r[f"{name}_{part}_full"]) for n, r in ((3, r3), (4, r4))
            }
            s[f"three_gt_four_{reading}"] = _frac(r3[f"{name}_{part}_reduced"], r4[f"{name}_{part}_reduced"])
        s["three_gt_four_sigma_2_full"] = _frac(r3[f"sigma_min_{part}_full"], r4[f"sigma_min_{part}_full"])
        s["three_gt_four_sigma_max"] = _frac(_sigma_max(r3, part), _sigma_max(r4, part))
        out["translation" if part == "v" else "orientation"] = s
    return out


def _sigma_max(r, part, mode="reduced"):
    """sigma_1 from the sweep: sigma_2 / KCI where the rank is 2, else the one non-zero value."""
    kci = r[f"kci_{part}_{mode}"]
    return np.where(
        kci > 0, r[f"sigma_min_{part}_{mode}"] / np.where(kci > 0, kci, 1.0), r[f"sigma_min_nz_{part}_{mode}"]
    )


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------
def _heat(ax, fig, theta_deg, delta_deg, Z, title, label, cmap="viridis", vmin=None, vmax=None, centre=None):
    from matplotlib.colors import TwoSlopeNorm

    norm = None
    if centre is not None:
        lo, hi = float(np.min(Z)), float(np.max(Z))
        lo, hi = min(lo, centre - 1e-9), max(hi, centre + 1e-9)
        norm = TwoSlopeNorm(vcenter=centre, vmin=lo, vmax=hi)
        vmin = vmax = None
    m = ax.pcolormesh(
        delta_deg, theta_deg, Z, shading="nearest", cmap=cmap, vmin=vmin, vmax=vmax, norm=norm, rasterized=True
    )
    ax.set_xlabel(r"bending direction $\delta$ (deg)")
    ax.set_ylabel(r"$\theta_L$ (deg)")
    ax.set_xticks(np.arange(0, 361, 90))
    ax.set_title(title, fontsize=10)
    cb = fig.colorbar(m, ax=ax, pad=0.02)
    cb.set_label(label)
    return m


def measure_figure(theta_deg, delta_deg, r3, r4, name, label_v, label_w, fig_title, path=None):
    """Figs. 9/10 layout: rows translation/orientation; columns (a) traditional 3 wires,
    (b) reduced 3 wires, (c) reduced 4 wires, (d) reduced 3 minus 4 wires.

    ``r3``, ``r4``: sweeps of :func:`tension_zones.analysis.pose_metrics`; ``name`` one of ``kci``,
    ``sigma_min``, ``sigma_min_nz``. Saved to ``path`` (and closed) if given, else returned.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 4, figsize=(19, 8.2), constrained_layout=True)
    for row, (part, label) in enumerate((("v", label_v), ("w", label_w))):
        a, b, c = r3[f"{name}_{part}_full"], r3[f"{name}_{part}_reduced"], r4[f"{name}_{part}_reduced"]
        top = float(max(a.max(), b.max(), c.max()))
        kind = "translation" if part == "v" else "orientation"
        letters = "abcd" if part == "v" else "efgh"
        _heat(
            axes[row, 0],
            fig,
            theta_deg,
            delta_deg,
            a,
            f"({letters[0]}) {kind}: traditional, 3 wires",
            label,
            vmin=0,
            vmax=top,
        )
        _heat(
            axes[row, 1],
            fig,
            theta_deg,
            delta_deg,
            b,
            f"({letters[1]}) {kind}: reduced, 3 wires",
            label,
            vmin=0,
            vmax=top,
        )
        _heat(
            axes[row, 2],
            fig,
            theta_deg,
            delta_deg,
            c,
            f"({letters[2]}) {kind}: reduced, 4 wires",
            label,
            vmin=0,
            vmax=top,
        )
        _heat(
            axes[row, 3],
            fig,
            theta_deg,
            delta_deg,
            b - c,
            f"({letters[3]}) {kind}: reduced, 3 wires minus 4 wires",
            "difference " + label,
            cmap="RdBu_r",
            centre=0.0,
        )
    fig.suptitle(fig_title, fontsize=13)
    return _save(fig, path)


def _save(fig, path):
    import matplotlib.pyplot as plt

    from .._io import save_figure

    if path is None:
        return fig
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def uncertainty_figure(
    theta_deg, delta_deg, results, q, dq=DQ, dq_values=DQ_SWEEP, fig_no=11, theta_profile=45.0, path=None
):
    """Figs. 11/12 for ``q`` = ``"position"`` or ``"orientation"``: (a) 3 wires and (b) 4 wires
    (reduced), (c) sensitivity to dq, (d) 3 over 4, (e) reduced over traditional for 3 wires,
    (f) a delta profile. ``results`` as returned by :func:`paper_sweeps`. Saved to ``path`` if given."""
    import matplotlib.pyplot as plt

    key, unit = QUANTITIES[q]
    r3, r4 = results[(3, dq)], results[(4, dq)]
    sym = r"\Delta p" if q == "position" else r"\Delta\omega"
    lab = f"max $\\|{sym}\\|$ ({unit})"
    fig, axes = plt.subplots(2, 3, figsize=(17, 9.5), constrained_layout=True)
    top = float(max(r3[f"{key}_reduced"].max(), r4[f"{key}_reduced"].max()))
    _heat(
        axes[0, 0],
        fig,
        theta_deg,
        delta_deg,
        r3[f"{key}_reduced"],
        f"(a) 3 wires, reduced Jacobian, dq = {dq} mm",
        lab,
        cmap="magma",
        vmin=0,
        vmax=top,
    )
    _heat(
        axes[0, 1],
        fig,
        theta_deg,
        delta_deg,
        r4[f"{key}_reduced"],
        f"(b) 4 wires, reduced Jacobian, dq = {dq} mm",
        lab,
        cmap="magma",
        vmin=0,
        vmax=top,
    )
    ax = axes[0, 2]
    for n, colour in ((3, "tab:red"), (4, "tab:blue")):
        for mode, ls in (("reduced", "-"), ("full", ":")):
            worst = [results[(n, x)][f"{key}_{mode}"].max() for x in dq_values]
            slope = np.polyfit(dq_values, worst, 1)[0]
            ax.plot(
                dq_values,
                worst,
                ls,
                marker="o",
                color=colour,
                label=f"{n} wires, {'reduced' if mode == 'reduced' else 'traditional'}: slope {slope:.3g} {unit}/mm",
            )
    ax.set_xlabel("joint-level uncertainty dq (mm)")
    ax.set_ylabel(f"workspace maximum of max $\\|{sym}\\|$ ({unit})")
    ax.set_title("(c) sensitivity to the joint-level uncertainty", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    _heat(
        axes[1, 0],
        fig,
        theta_deg,
        delta_deg,
        r3[f"{key}_reduced"] / r4[f"{key}_reduced"],
        "(d) 3 wires over 4 wires (reduced), pointwise",
        "ratio 3 wires / 4 wires",
        cmap="RdBu_r",
        centre=1.0,
    )
    _heat(
        axes[1, 1],
        fig,
        theta_deg,
        delta_deg,
        r3[f"{key}_reduced"] / r3[f"{key}_full"],
        "(e) 3 wires: reduced over traditional",
        "ratio reduced / traditional",
        cmap="RdBu_r",
        centre=1.0,
    )
    ax = axes[1, 2]
    i = int(np.argmin(np.abs(theta_deg - theta_profile)))
    for n, r, colour in ((3, r3, "tab:red"), (4, r4, "tab:blue")):
        ax.plot(delta_deg, r[f"{key}_reduced"][i], "-", color=colour, label=f"{n} wires, reduced")
        note = " (= reduced off the wire lines)" if n == 4 else ""
        ax.plot(delta_deg, r[f"{key}_full"][i], ":", color=colour, label=f"{n} wires, traditional{note}")
    ax.set_xlabel(r"bending direction $\delta$ (deg)")
    ax.set_ylabel(lab)
    ax.set_xticks(np.arange(0, 361, 60))
    ax.set_title(f"(f) profile at $\\theta_L$ = {theta_deg[i]:g} deg, dq = {dq} mm", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    fig.suptitle(
        f"Fig. {fig_no}: end-disk {q} uncertainty from joint-level uncertainty "
        f"(L = {LENGTH:g} mm, r = {PITCH_RADIUS:g} mm)",
        fontsize=13,
    )
    return _save(fig, path)


def reproduce_kinematics(out: Path, summary: dict, quiet: bool) -> list[Path]:
    """``tension-zones reproduce`` step for Sec. 6.1: Figs. 9-12 and ``summary["uncertainty"]``."""
    theta_deg, delta_deg, results = paper_sweeps(quiet=quiet)
    r3, r4 = results[(3, DQ)], results[(4, DQ)]
    written = [
        measure_figure(
            theta_deg,
            delta_deg,
            r3,
            r4,
            "kci",
            "KCI",
            "KCI",
            "Fig. 9: kinematic conditioning index (KCI) of the translational (top) and "
            "orientational (bottom) Jacobians",
            path=out / "fig9_kci.png",
        ),
        measure_figure(
            theta_deg,
            delta_deg,
            r3,
            r4,
            "sigma_min",
            r"$\sigma_{min}$ (mm/mm)",
            r"$\sigma_{min}$ (rad/mm)",
            r"Fig. 10: minimal singular value $\sigma_{min} = \sigma_2$ "
            f"(0 where the rank is 1), L = {LENGTH:g} mm, r = {PITCH_RADIUS:g} mm",
            path=out / "fig10_sigma_min.png",
        ),
        measure_figure(
            theta_deg,
            delta_deg,
            r3,
            r4,
            "sigma_min_nz",
            r"$\sigma_{min,nz}$ (mm/mm)",
            r"$\sigma_{min,nz}$ (rad/mm)",
            "Fig. 10, other reading: smallest non-zero singular value (the single "
            "actuated direction's gain in one-wire zones)",
            path=out / "fig10_sigma_min_nz.png",
        ),
        uncertainty_figure(
            theta_deg, delta_deg, results, "position", fig_no=11, path=out / "fig11_position_uncertainty.png"
        ),
        uncertainty_figure(
            theta_deg, delta_deg, results, "orientation", fig_no=12, path=out / "fig12_orientation_uncertainty.png"
        ),
    ]
    summary["uncertainty"] = uncertainty_summary(results)
    summary["kinematics"] = kinematics_summary(results)
    return written
