"""Figures. Matplotlib only, Agg backend by default; every function takes an optional ``ax``."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib


def _choose_backend() -> None:
    """The package's one choice of Matplotlib backend: headless (Agg) by default; an IPython session
    (a notebook's inline backend, an interactive one) keeps its own."""
    if matplotlib.get_backend().lower() in ("agg", "module://matplotlib_inline.backend_inline"):
        return
    try:
        import IPython

        if IPython.get_ipython() is None:
            matplotlib.use("Agg")
    except ImportError:
        matplotlib.use("Agg")


_choose_backend()

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Wedge

from ._io import staged_folder, write_json
from .design._explore import STATS, UNITS, objective, pareto_front, structure_groups, write_csv
from .design._optimise import INFEASIBLE_RANK, wires_label
from .model._zones import TensionMap


def pyplot():
    """``matplotlib.pyplot``, with the backend chosen as above (for figures made outside this module)."""
    return plt


_COUNT_COLOURS = {0: "#d62728", 1: "#fdd49e", 2: "#9ecae1", 3: "#74c476", 4: "#31a354"}
#: Above this many wires a map has too many sectors and rings to label each: the sectors are then
#: told apart by colour (legend: taut count), some rings are numbered, and the full sector list is
#: the printed table (``TensionMap.table``).
LABEL_MAX_WIRES = 12


def _count_colour(k: int, counts) -> tuple | str:
    """The shade of a sector with ``k`` taut wires; ``counts``: the counts the map has. Few wires:
    the paper's fixed shades; otherwise one colour scale over the counts present."""
    if max(counts) <= 4:
        return _COUNT_COLOURS[k]
    lo, hi = min(counts), max(counts)
    return plt.get_cmap("viridis")(0.15 + 0.8 * (k - lo) / max(hi - lo, 1))


def _wire_colour(k: int, n: int):
    return plt.get_cmap("tab10" if n <= 10 else "tab20")(k % (10 if n <= 10 else 20))


def plot_tension_map(tmap: TensionMap, ax=None, title: str | None = None):
    """Draw a tension map in the paper's style (Figs. 2, 5, 7).

    The inner disk is split into the sectors of constant taut set, shaded by the number of taut
    wires and labelled with the wires; each wire's 180 deg zone is an offset ring outside it (wire 1
    innermost). Angles are the bending-plane angle ``delta`` (deg), counter-clockwise from x.
    Point sectors (a single direction with fewer taut wires) are drawn as dashed rays. Above
    :data:`LABEL_MAX_WIRES` wires the rings are thinner and only every few is numbered, sectors are
    labelled by their taut count where they are wide enough, and rays carry no count.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(6.4, 6.4))
    n = tmap.n_wires
    many = n > LABEL_MAX_WIRES
    ring0, ring_w = 1.08, (0.09 if not many else 1.1 / n)  # the ring band stays within ~1.1
    sectors = list(tmap.sectors)
    present = sorted({s.n_taut for s in sectors if s.width_deg > 0}) or [0]
    sectors = _whole_sectors(sectors)
    for s in sectors:
        if s.width_deg > 0:
            _draw_sector(ax, s, present, many)
        else:
            _draw_ray(ax, s, many)
    _draw_zones(ax, tmap, ring0, ring_w, many)
    r_max = ring0 + (n + 1) * ring_w
    _draw_angle_ticks(ax, r_max)
    ax.add_patch(plt.Circle((0, 0), 1.0, fill=False, color="0.2", lw=0.8))
    _draw_count_legend(ax, present, any(s.width_deg == 0 for s in sectors), many)
    lim = r_max + 0.3
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.axis("off")
    if title is None:
        title = f"Tension map, {n} wires"
        if tmap.phase_deg:
            title += f" (zones shifted {tmap.phase_deg:.1f}° by δ̇)"
    ax.set_title(title + "\nbending-plane angle δ; inner: taut wires; rings: each wire's zone", fontsize=10)
    return ax


def _whole_sectors(sectors: list) -> list:
    """The map's sectors with the one through 0 deg whole (the table splits it in two)."""
    first, last = sectors[0], sectors[-1]
    if len(sectors) > 1 and first.width_deg > 0 and last.width_deg > 0 and first.wires == last.wires:
        return [type(first)(last.start_deg, first.end_deg + 360.0, first.wires)] + sectors[1:-1]
    return sectors


def _draw_sector(ax, s, present, many: bool) -> None:
    """A sector of constant taut set: a wedge of the inner disk shaded by its taut count (``present``:
    the counts the map has), labelled with its wires (``many``: with its count, where wide enough)."""
    ax.add_patch(
        Wedge(
            (0, 0),
            1.0,
            s.start_deg,
            s.end_deg,
            fc=_count_colour(s.n_taut, present),
            ec="white",
            lw=1.0 if not many else 0.4,
        )
    )
    mid = np.radians(0.5 * (s.start_deg + s.end_deg))
    rad = 0.62 if s.width_deg > 25 else 0.8
    if not many:
        label = ",".join(map(str, s.wires)) or "none"
    elif s.width_deg >= 20:
        label = f"{s.n_taut}"
    else:
        return
    ax.text(rad * np.cos(mid), rad * np.sin(mid), label, ha="center", va="center", fontsize=9)


def _draw_ray(ax, s, many: bool) -> None:
    """A point sector (one direction): a dashed ray, its taut count circled (not with ``many`` wires)."""
    a = np.radians(s.start_deg)
    ax.plot([0, np.cos(a)], [0, np.sin(a)], ls="--", color="k", lw=1.2 if not many else 0.5)
    if not many:
        ax.text(
            1.0 * np.cos(a) * 0.45,
            1.0 * np.sin(a) * 0.45,
            f"{s.n_taut}",
            fontsize=8,
            ha="center",
            va="center",
            bbox={"boxstyle": "circle,pad=0.15", "fc": "white", "ec": "k", "lw": 0.6},
        )


def _draw_zones(ax, tmap: TensionMap, ring0: float, ring_w: float, many: bool) -> None:
    """Each wire's zone as a ring of width ``ring_w`` outside radius ``ring0`` (wire 1 innermost),
    numbered (with ``many`` wires, every few)."""
    n = tmap.n_wires
    ring_step = 1 if not many else math.ceil(n / LABEL_MAX_WIRES)
    for k, (a, b) in enumerate(tmap.zones_deg):
        r_out = ring0 + (k + 1) * ring_w
        ax.add_patch(Wedge((0, 0), r_out, a, b, width=ring_w * 0.8, fc=_wire_colour(k, n), ec="none", alpha=0.85))
        if k % ring_step == 0:
            mid = np.radians(0.5 * (a + b))
            r_txt = r_out - (0.04 if not many else 0.4 * ring_w)
            ax.text(
                r_txt * np.cos(mid),
                r_txt * np.sin(mid),
                str(k + 1),
                ha="center",
                va="center",
                fontsize=7 if not many else 5,
                color="white" if not many else "k",
                fontweight="bold",
            )


def _draw_angle_ticks(ax, r_max: float) -> None:
    """Ticks and labels of the bending-plane angle every 30 deg outside radius ``r_max``."""
    for deg in range(0, 360, 30):
        a = np.radians(deg)
        ax.plot(
            [r_max * np.cos(a), (r_max + 0.04) * np.cos(a)],
            [r_max * np.sin(a), (r_max + 0.04) * np.sin(a)],
            color="0.3",
            lw=0.8,
        )
        ax.text(
            (r_max + 0.13) * np.cos(a),
            (r_max + 0.13) * np.sin(a),
            f"{deg}°",
            ha="center",
            va="center",
            fontsize=8,
            color="0.3",
        )


def _draw_count_legend(ax, present, rays: bool, many: bool) -> None:
    """A legend of the taut counts (at most eight entries), and of the rays where the map has any."""
    counts = present if len(present) <= 8 else present[:: math.ceil(len(present) / 8)]
    handles: list = [plt.Rectangle((0, 0), 1, 1, fc=_count_colour(k, present)) for k in counts]
    labels = [f"{k} taut" for k in counts]
    if rays:
        handles.append(plt.Line2D([], [], ls="--", color="k"))
        labels.append("single direction" + (" (circled: taut count)" if not many else ""))
    ax.legend(handles, labels, loc="lower left", fontsize=8, frameon=False, bbox_to_anchor=(-0.05, -0.08))


def plot_tradeoff(result: dict, path):
    """Each objective term of the best design of every wire count against the count (several
    segments: of every combination of counts, ``"4+3"``); a deflection not computed (weight 0) is NaN,
    an empty panel."""
    rows = [r for r in result["per_wire_count"] if "objective" in r]
    terms = [
        ("worst_position_uncertainty_mm", "worst position uncertainty (mm)"),
        ("worst_deflection_mm", "worst reduced deflection (mm)"),
        ("objective", "objective"),
    ]
    several = result.get("segments", 1) > 1
    fig, axes = plt.subplots(1, len(terms), figsize=(4 * len(terms), 3.8))
    n = list(range(len(rows))) if several else [r["n_wires"] for r in rows]
    feas = [r["feasible"] for r in rows]
    for ax, (key, label) in zip(axes, terms):
        y = [r[key] for r in rows]
        ax.plot(n, y, "-", color="0.6")
        ax.scatter(
            [a for a, f in zip(n, feas) if f],
            [b for b, f in zip(y, feas) if f],
            color="tab:blue",
            zorder=3,
            label="feasible",
        )
        ax.scatter(
            [a for a, f in zip(n, feas) if not f],
            [b for b, f in zip(y, feas) if not f],
            color="tab:red",
            marker="x",
            zorder=3,
            label="infeasible",
        )
        ax.set_xlabel("wires per segment, proximal first" if several else "number of wires")
        ax.set_ylabel(label)
        ax.set_xticks(n, [wires_label(r["n_wires"]) for r in rows])
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    best = result.get("best")
    fig.suptitle(
        "Trade-off against the wire count"
        + (f" (best: {wires_label(best['n_wires'])} wires)" if best else " (no feasible design)")
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_convergence(result: dict, path, infeasible_rank: float):
    """Best-so-far exact objective per Adam step, one line per wire count (best start)."""
    fig, ax = plt.subplots(figsize=(6.4, 4))
    for n, hist in result["history"].items():
        h = np.asarray(hist, dtype=float)
        h = np.where(h >= infeasible_rank, np.nan, h)  # infeasible so far: not drawn
        ax.plot(np.arange(1, h.size + 1), h, label=f"{n} wires")
    ax.set_xlabel("Adam step")
    ax.set_ylabel("best feasible objective so far")
    ax.set_title("Convergence (best of the starts; gaps: no feasible design yet)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ---- design-space exploration --------------------------------------------------------
def _label(column: str) -> str:
    """An exploration column (``name``, ``min:name`` or ``max:name``) with its unit and which way is better."""
    name, best = objective(column)
    unit = next((u for k, u in UNITS.items() if name.startswith(k)), "")
    unit = {"mm": " (mm)", "rad": " (rad)", "deg": " (deg)"}.get(unit, "")
    return f"{name}{unit}, {'higher' if best == 'max' else 'lower'} is better"


def _by_wire_count(table):
    """``[(n, rows, colour)]`` for each wire count of an exploration table (several segments: each
    combination, ``n`` its label)."""
    return [(n, rows, plt.get_cmap("tab10")(i % 10)) for i, (n, rows) in enumerate(structure_groups(table))]


def plot_front(table: dict, columns, front, path=None):
    """Every design of an exploration (colour: wire count) and its Pareto ``front`` (bool
    per design, black-edged), for two columns (one scatter, the front joined as a staircase) or three
    (the three pairs side by side); ``min:``/``max:`` prefixes as in ``pareto_front``. Saves to
    ``path`` if given; returns the figure."""
    labels, columns = list(columns), [objective(c)[0] for c in columns]
    pairs = [(0, 1)] if len(columns) == 2 else [(0, 1), (0, 2), (1, 2)]
    fig, axes = plt.subplots(1, len(pairs), figsize=(5.6 * len(pairs), 4.6), squeeze=False)
    front = np.asarray(front, bool)
    for ax, (i, j) in zip(axes[0], pairs):
        x, y = (np.asarray(table[columns[k]], float) for k in (i, j))
        for n, rows, colour in _by_wire_count(table):
            ax.scatter(x[rows & ~front], y[rows & ~front], s=6, color=colour, alpha=0.35, lw=0, label=f"{n} wires")
            ax.scatter(x[rows & front], y[rows & front], s=34, color=colour, edgecolor="k", lw=0.8, zorder=3)
        if len(columns) == 2 and front.any():
            # the edge of what the front dominates: a point's value holds until the next point when x
            # is minimised (it dominates larger x), from the previous one when x is maximised
            order = np.argsort(x[front])
            where = "post" if objective(labels[0])[1] == "min" else "pre"
            ax.step(x[front][order], y[front][order], where=where, color="k", lw=0.8, zorder=2)
        ax.set_xlabel(_label(labels[i]), fontsize=9)
        ax.set_ylabel(_label(labels[j]), fontsize=9)
        ax.grid(alpha=0.3)
    handles = axes[0][0].get_legend_handles_labels()[0]
    handles.append(plt.Line2D([], [], ls="", marker="o", mfc="w", mec="k", label="Pareto front"))
    axes[0][0].legend(handles=handles, fontsize=8, markerscale=1.5)
    fig.suptitle(
        f"{len(front)} designs, {int(front.sum())} on the Pareto front of\n"
        f"{', '.join(columns)}" + (" (projected)" if len(columns) == 3 else ""),
        fontsize=10,
    )
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig


def plot_parallel(table: dict, columns, front, path=None, fields=None, max_lines: int = 1500):
    """Parallel coordinates of an exploration: ``fields`` (default: every design field that
    varies, but the wire angles, whose meaning changes with the wire count) and the front's
    ``columns``, each axis scaled to its range (ends labelled). Front designs are coloured by wire
    count, the others grey (at most ``max_lines`` of them, evenly picked). Returns the figure."""
    from matplotlib.collections import LineCollection

    columns = [objective(c)[0] for c in columns]

    def varies(v):
        v = np.asarray(v, float)
        return np.unique(v[np.isfinite(v)]).size > 1

    if fields is None:
        fields = [
            k
            for k in table
            if k != "design" and k not in STATS and k not in columns and "wire_angle_" not in k and varies(table[k])
        ]
    axes_names = fields + list(columns)
    V = np.stack([np.asarray(table[k], float) for k in axes_names], axis=1)
    lo, hi = np.nanmin(V, axis=0), np.nanmax(V, axis=0)
    U = (V - lo) / np.where(hi > lo, hi - lo, 1.0)
    front = np.asarray(front, bool)
    xs = np.arange(len(axes_names))
    fig, ax = plt.subplots(figsize=(max(6.0, 1.7 * len(axes_names)), 4.8))
    rest = np.flatnonzero(~front)
    rest = rest[np.linspace(0, rest.size - 1, min(rest.size, max_lines)).astype(int)] if rest.size else rest
    ax.add_collection(LineCollection([np.column_stack([xs, U[i]]) for i in rest], colors="0.7", lw=0.4, alpha=0.4))
    for n, rows, colour in _by_wire_count(table):
        sel = np.flatnonzero(rows & front)
        ax.add_collection(
            LineCollection(
                [np.column_stack([xs, U[i]]) for i in sel],
                colors=[colour],
                lw=1.2,
                label=f"front, {n} wires ({sel.size})",
            )
        )
    for k, name in enumerate(axes_names):
        ax.axvline(k, color="k", lw=0.6)
        ax.text(k, -0.06, f"{lo[k]:.3g}", ha="center", va="top", fontsize=7)
        ax.text(k, 1.04, f"{hi[k]:.3g}", ha="center", va="bottom", fontsize=7)
    ax.set_xticks(xs)
    ax.set_xticklabels(axes_names, rotation=25, ha="right", fontsize=8)
    ax.set_xlim(-0.3, len(axes_names) - 0.7)
    ax.set_ylim(-0.12, 1.12)
    ax.set_yticks([])
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax.set_title(
        f"Parallel coordinates: {int(front.sum())} front designs (colour), "
        f"{rest.size} of the others (grey); axes scaled min..max",
        fontsize=10,
    )
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig


def write_front(table: dict[str, np.ndarray], out, columns: Sequence[str]) -> list[Path]:
    """``front.csv`` (the front's rows), ``front.png`` (scatter with the front) and
    ``parallel.png`` (parallel coordinates) in ``out``; returns their paths."""
    out = Path(out)
    on = pareto_front(table, columns)
    names = ["front.csv", "front.png", "parallel.png"]
    with staged_folder(out) as stage:
        write_csv({k: v[on] for k, v in table.items()}, stage / names[0])
        plot_front(table, columns, on, stage / names[1])
        plot_parallel(table, columns, on, stage / names[2])
    return [out / n for n in names]


# ---- the design commands' output folders ----------------------------------------------
#: The files :func:`write_outputs` writes into its folder.
OUTPUT_FILES = ("result.json", "tradeoff.png", "convergence.png")


def write_outputs(result: dict[str, Any], out_dir) -> list:
    """``result.json`` (without the history; figures not computed are ``null``), ``tradeoff.png`` and
    ``convergence.png``, made in a staging folder and moved in together, ``result.json`` last
    (:func:`tension_zones._io.staged_folder`): an interrupted write leaves none of them."""
    out = Path(out_dir)
    paths = [out / name for name in OUTPUT_FILES]
    with staged_folder(out, last=OUTPUT_FILES[:1]) as stage:
        write_json(stage / OUTPUT_FILES[0], {k: v for k, v in result.items() if k != "history"})
        plot_tradeoff(result, stage / OUTPUT_FILES[1])
        plot_convergence(result, stage / OUTPUT_FILES[2], INFEASIBLE_RANK)
    return paths


def plot_segment_maps(rows, wires):
    """A robot's tension maps: one row per bending of the other segments, one panel per segment.

    ``rows``: ``[(label, [TensionMap of segment j, ...]), ...]``; ``wires[j]``: the robot's wires
    (1-based) crossing segment ``j``, the map's wires 1.. in order (:func:`~tension_zones.model._chain_zones.crossing_wires`).
    """
    n_rows, S = len(rows), len(rows[0][1])
    fig, axes = plt.subplots(n_rows, S, figsize=(6.4 * S, 6.0 * n_rows), squeeze=False)
    for r, (label, maps) in enumerate(rows):
        for j, tmap in enumerate(maps):
            first = int(wires[j][0])
            title = f"segment {j + 1} of {S}, {label}\nmap wire k = robot wire {first} + k - 1"
            plot_tension_map(tmap, ax=axes[r][j], title=title)
    return fig
