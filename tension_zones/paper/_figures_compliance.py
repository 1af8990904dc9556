"""Paper Sec. 6.2 reproduced: identification, Figs. 13-14 and Tables 1-2 (``tension-zones reproduce``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model._design import Design
from ..model._statics import PAPER_WRENCH, compliance_grid
from ._identify import FIT_KEYS, PAPER_REDUCED_OVER_TRADITIONAL_3, PAPER_TABLE, identify

K_VALUES = (55.0, 65.0, 75.0, 85.0, 95.0, 105.0)
COLORS = {3: "tab:red", 4: "tab:blue"}


def _stats(g, mode):
    mm, deg = g[f"deflection_mm_{mode}"], g[f"deflection_deg_{mode}"]
    return [float(mm.mean()), float(mm.std(ddof=1)), float(deg.mean()), float(deg.std(ddof=1))]


def _band(ax, g, key, color, label, ls="-"):
    """theta_L-mean of a grid quantity vs delta, with its min-max band over theta_L."""
    x, y = g["delta_deg"], g[key]
    ax.plot(x, y.mean(axis=0), color=color, ls=ls, label=label)
    ax.fill_between(x, y.min(axis=0), y.max(axis=0), color=color, alpha=0.15, lw=0)


def fig13(grids, path: Path):
    """2 x 4 panels: rows linear / angular; columns reduced / traditional x preload 0 / 5 N."""
    import matplotlib.pyplot as plt

    cols = [("reduced", 0.0, "a", "b"), ("reduced", 5.0, "c", "d"), ("full", 0.0, "e", "f"), ("full", 5.0, "g", "h")]
    fig, axes = plt.subplots(2, 4, figsize=(17, 7.5), sharex=True, sharey="row")
    for j, (mode, pre, la, lb) in enumerate(cols):
        name = "reduced" if mode == "reduced" else "traditional"
        for i, (q, unit, letter) in enumerate((("mm", "mm", la), ("deg", "deg", lb))):
            ax = axes[i, j]
            for n in (3, 4):
                _band(ax, grids[(n, 75.0, pre)], f"deflection_{q}_{mode}", COLORS[n], f"{n} wires")
            ax.set_title(f"({letter}) {name}, preload {pre:g} N", fontsize=10)
            if i == 1:
                ax.set_xlabel(r"bending direction $\delta$ (deg)")
            if j == 0:
                ax.set_ylabel(("position" if q == "mm" else "angular") + f" deflection ({unit})")
            ax.set_xticks(np.arange(0, 361, 60))
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8, loc="upper right")
    fig.suptitle(
        "Fig. 13: tip deflection under w = [5 N, 0, 0, 0, 0, 0] (base frame), k_w = 75 N/mm; "
        r"line: mean over $\theta_L$ = 89..45 deg, band: min-max",
        fontsize=11,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def fig14(grids, path: Path):
    """2 x 2 panels: reduced / traditional x linear / angular, k_w = 55..105 N/mm, no preload."""
    import matplotlib as mpl
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    cmap, norm = mpl.colormaps["viridis"], mpl.colors.Normalize(min(K_VALUES), max(K_VALUES))
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5), sharex=True)
    panels = [("reduced", "mm", "a"), ("reduced", "deg", "b"), ("full", "mm", "c"), ("full", "deg", "d")]
    for ax, (mode, q, letter) in zip(axes.ravel(), panels):
        for k in K_VALUES:
            for n, ls in ((3, "-"), (4, "--")):
                y = grids[(n, k, 0.0)][f"deflection_{q}_{mode}"].mean(axis=0)
                ax.plot(grids[(n, k, 0.0)]["delta_deg"], y, color=cmap(norm(k)), ls=ls)
        name = "reduced" if mode == "reduced" else "traditional"
        kind = "position" if q == "mm" else "angular"
        ax.set_title(f"({letter}) {name}, {kind} deflection", fontsize=10)
        ax.set_ylabel(f"{kind} deflection ({q}), mean over " + r"$\theta_L$")
        if letter in "cd":
            ax.set_xlabel(r"bending direction $\delta$ (deg)")
        ax.set_xticks(np.arange(0, 361, 60))
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    handles = [Line2D([], [], color="k", ls="-", label="3 wires"), Line2D([], [], color="k", ls="--", label="4 wires")]
    axes[0, 0].legend(handles=handles, fontsize=9)
    fig.colorbar(mpl.cm.ScalarMappable(norm=norm, cmap=cmap), ax=axes, label="wire stiffness k_w (N/mm)")
    fig.suptitle("Fig. 14: deflection for wire stiffness 55..105 N/mm (no preload)", fontsize=11)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def _table_text(table, fit, ratios):
    rows = [
        "Identified (Levenberg-Marquardt on the twelve means of Tables 1-2):",
        (
            f"  L = {fit['length_mm']:.3f} mm, r = {fit['pitch_radius_mm']:.3f} mm, "
            f"EI = {fit['backbone_EI_Nmm2']:.2f} N mm^2; mean |relative error| = "
            f"{100 * fit['mean_relative_error']:.2f} %"
        ),
        "",
        "Tables 1-2 (reduced, no preload): ours vs paper, mean (SD); error of the mean",
        f"{'wires':>5} {'k_w':>5} {'position (mm)':>34} {'angle (deg)':>34}",
    ]
    err = dict(zip(FIT_KEYS, fit["relative_errors"]))
    for n in (3, 4):
        for k in (55, 75, 105):
            o, p = table[str(n)][str(k)], PAPER_TABLE[n][k]
            rows.append(
                f"{n:>5} {k:>5} {o[0]:7.3f} ({o[1]:.3f}) vs {p[0]:6.3f} ({p[1]:.3f}) {100 * err[(n, k, 'mm')]:+5.1f}%"
                f" {o[2]:7.2f} ({o[3]:.2f}) vs {p[2]:6.2f} ({p[3]:.2f}) {100 * err[(n, k, 'deg')]:+5.1f}%"
            )
    rows += [
        "",
        (
            "Reduced / traditional mean position deflection (k_w = 75, no preload): "
            f"3 wires {ratios['3']:.3f} (paper: +206 % = {PAPER_REDUCED_OVER_TRADITIONAL_3}), "
            f"4 wires {ratios['4']:.3f}"
        ),
    ]
    return "\n".join(rows)


def compliance_step(out: Path, summary: dict, quiet: bool) -> list[Path]:
    """Paper Sec. 6.2: identify (L, r, EI), then Figs. 13-14 and Tables 1-2."""
    fit = identify()
    L, r, EI = fit["length_mm"], fit["pitch_radius_mm"], fit["backbone_EI_Nmm2"]
    grids = {}
    for n in (3, 4):
        for k in K_VALUES:
            for pre in (0.0, 5.0) if k == 75.0 else (0.0,):
                d = Design(n, L, r, wire_stiffness=k, backbone_EI=EI, preload=pre)
                grids[(n, k, pre)] = compliance_grid(d, PAPER_WRENCH)
    table = {str(n): {str(int(k)): _stats(grids[(n, k, 0.0)], "reduced") for k in (55.0, 75.0, 105.0)} for n in (3, 4)}
    ratios = {
        str(n): _stats(grids[(n, 75.0, 0.0)], "reduced")[0] / _stats(grids[(n, 75.0, 0.0)], "full")[0] for n in (3, 4)
    }
    summary["compliance"] = {
        "identified": {"length_mm": L, "pitch_radius_mm": r, "backbone_EI_Nmm2": EI},
        "table": table,
        "reduced_over_traditional_position_mean": ratios,
    }
    text = _table_text(table, fit, ratios)
    if not quiet:
        print(text)
    written = [out / "fig13_compliance.png", out / "fig14_wire_stiffness.png", out / "compliance_tables.txt"]
    fig13(grids, written[0])
    fig14(grids, written[1])
    written[2].write_text(text + "\n")
    return written
