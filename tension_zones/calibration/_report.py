"""Writing a calibration's outcome: ``report.json``, ``report.md`` and the plots, for any robot.

Plots: the residual against the bending direction and against the direction of motion, before and
after the effects (``residual_vs_*.png``), and the measured against the predicted tip path
(``tip_paths.png``: on the validation file when one is given, else on the held-out part).
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np

from .._io import save_figure, staged_folder
from ._design_file import calibrated_design
from ._fits import SCREEN_ITERATIONS, rmse
from ._loop import EXCESS_RATIO, SECOND_LOOK_SHARE, STRUCTURE_Z, Result

PLOTS = {
    "bending_direction": "residual_vs_bending_direction.png",
    "motion": "residual_vs_motion.png",
}
PATHS_PLOT = "tip_paths.png"
#: The files a report folder holds (a new report never silently replaces them).
#: The calibrated robot as a design file, for every design command's ``--design``.
DESIGN_FILE = "calibrated.design.json"
FILES = ("report.json", "report.md", DESIGN_FILE, *PLOTS.values(), PATHS_PLOT)


def _pyplot():
    from ..plots import pyplot  # the package's one choice of backend

    return pyplot()


#: Fixed margins (the figures' sizes and labels are fixed): ``tight_layout`` would draw every figure
#: an extra time to measure them.
_RESIDUAL_GRID = {"left": 0.06, "right": 0.99, "bottom": 0.08, "top": 0.87, "wspace": 0.06, "hspace": 0.16}
_PATHS_GRID = {"left": 0.06, "right": 0.99, "bottom": 0.08, "top": 0.95, "wspace": 0.22, "hspace": 0.3}


def _components(r, feats):
    """Residual (N, 3) as radial (along the bending direction), tangential and axial parts."""
    c, s = np.cos(feats["bending_direction"]), np.sin(feats["bending_direction"])
    return np.stack([c * r[:, 0] + s * r[:, 1], -s * r[:, 0] + c * r[:, 1], r[:, 2]], axis=1)


def plot_residuals(res: Result, out_dir: Path) -> list[Path]:
    """Residual against bending direction and against direction of motion, before and after."""
    plt = _pyplot()
    pb, feats = res.problem, res.features
    mask = res.train | res.held
    # the fits on the training part: the held-out samples' residuals are out of sample
    comps = {
        "before (nominal fit)": _components(pb.residuals(res.theta_before, res.nominal), feats),
        "after": _components(pb.residuals(res.theta_selected, res.active), feats),
    }
    # the effects added go on a line of their own: in the panels' titles a long list runs into its neighbours
    added = textwrap.fill("after: " + (", ".join(e.name for e in res.effects) or "no effect added"), 150)
    lim = 1.1 * max(np.percentile(np.abs(c[mask]), 99.5) for c in comps.values())
    xlabels = {
        "bending_direction": "bending direction (deg, base frame)",
        "motion": "motion rel. to bending dir. (deg; 0 = bending further)",
    }
    paths = []
    for feat, fname in PLOTS.items():
        x = np.degrees(feats[feat])
        fig, axes = plt.subplots(2, 3, figsize=(13, 6.5), sharex=True, sharey=True, gridspec_kw=_RESIDUAL_GRID)
        for row, (title, c) in enumerate(comps.items()):
            for col, lab in enumerate(["radial", "tangential", "axial (z)"]):
                ax = axes[row, col]
                ax.scatter(x[res.train], c[res.train, col], s=6, c="0.7", label="training")
                ax.scatter(x[res.held], c[res.held, col], s=9, c="C3", label="held out")
                ax.axhline(0.0, color="k", lw=0.6)
                for sgn in (-1, 1):
                    ax.axhline(sgn * 2 * np.mean(res.noise["sigma_mm"]), color="C0", lw=0.6, ls="--")
                ax.set_ylim(-lim, lim)
                ax.set_title(f"{title}: {lab}", fontsize=9)
                if col == 0:
                    ax.set_ylabel("residual (mm)")
                if row == 1:
                    ax.set_xlabel(xlabels[feat], fontsize=8)
        axes[0, 0].legend(fontsize=7, loc="upper right")
        fig.suptitle(
            f"{Path(pb.data.source).name}: measured - predicted tip position (dashed: +-2 noise sigma)\n{added}",
            fontsize=10,
        )
        path = out_dir / fname
        _save(fig, path)
        plt.close(fig)
        paths.append(path)
    return paths


def plot_paths(res: Result, out_dir: Path) -> Path:
    """Measured vs predicted tip paths (validation file, else the held-out part): top view and
    x, y, z in acquisition order, with the best black-box baseline where there is one."""
    plt = _pyplot()
    on_val = bool(res.val.any())
    mask = res.val if on_val else res.held
    m = res.problem.data.p[mask]
    # the validation file by the final model (refitted on every sample), the held-out part by the fit
    # that never saw it
    p = res.predicted(None if on_val else res.theta_selected)[mask]
    err = rmse(p - m)
    what = "validation file" if on_val else "held-out part"
    best = None
    if on_val and res.baselines:
        best = min(res.baselines.items(), key=lambda kv: kv[1]["rmse_validate_mm"])
    fig = plt.figure(figsize=(13, 6.5))
    fig.subplots_adjust(**_PATHS_GRID)
    ax = fig.add_subplot(1, 2, 1)
    ax.plot(m[:, 0], m[:, 1], ".-", color="k", lw=0.6, ms=2.5, label="measured")
    ax.plot(p[:, 0], p[:, 1], ".-", color="C3", lw=0.6, ms=2.5, label=f"model ({err:.2f} mm RMSE)")
    if best:
        bp = np.asarray(best[1]["predicted"])
        ax.plot(
            bp[:, 0],
            bp[:, 1],
            "-",
            color="C0",
            lw=0.5,
            alpha=0.6,
            label=f"{best[0]} baseline ({best[1]['rmse_validate_mm']:.2f} mm)",
        )
    ax.set_aspect("equal")
    ax.set_xlabel("tip x (mm)")
    ax.set_ylabel("tip y (mm)")
    ax.set_title(f"{what}, top view")
    ax.legend(fontsize=8, loc="best")
    for i, c in enumerate("xyz"):
        axi = fig.add_subplot(3, 2, 2 * i + 2)
        axi.plot(m[:, i], color="k", lw=0.8, label="measured")
        axi.plot(p[:, i], color="C3", lw=0.8, label="model")
        axi.set_ylabel(f"tip {c} (mm)")
        if i == 2:
            axi.set_xlabel(f"sample of the {what}")
        if i == 0:
            axi.legend(fontsize=8, loc="upper right")
            axi.set_title("measured vs predicted, in acquisition order")
    path = out_dir / PATHS_PLOT
    _save(fig, path)
    plt.close(fig)
    return path


def _save(fig, path: Path) -> None:
    save_figure(fig, path, dpi=110, format="png")


def _fmt_params(params: dict, std: dict | None = None) -> str:
    std = std or {}
    return ", ".join(
        f"{k} = {v:.4g}" + (f" +- {std[k]:.2g}" if std.get(k) is not None else "") for k, v in params.items()
    )


def _f(x, nd=4):
    return "-" if x is None else f"{x:.{nd}f}"


def markdown(report: dict) -> str:
    """``report.md``: the summary, before and after, what was found, the evidence round by round, the
    structure left, the final parameters and the plots."""
    lines = (
        _md_summary(report)
        + _md_before_after(report)
        + _md_found(report)
        + _md_evidence(report)
        + _md_structure(report)
        + _md_parameters(report)
    )
    return "\n".join(lines) + "\n"


def _md_summary(report: dict) -> list[str]:
    val = "rmse_validate_mm" in report
    lines = [f"# Calibration report: `{Path(report['data']).name}`", ""]
    lines += [
        f"{report['n_samples']} samples ({report['dropped_rows']} bad rows dropped); training: "
        f"{report['n_train']}, held out: {report['n_held_out']} ({report['holdout']}). "
        + (
            f"Validation: `{Path(report['validate']).name}`, {report['n_validate']} samples, only predicted "
            "after the selection. "
            if val and report.get("validate")
            else ""
        )
        + f"Held-out errors are those of the models fitted on the training part; the chosen model is then "
        f"refitted on all {report['n_samples']} samples (RMSE {_f(report.get('rmse_refit_mm'))} mm on them), and "
        f"its parameters{' and validation errors' if val else ''} are that fit's. "
        + f"Loss: {'Huber (robust)' if report['robust'] else 'least squares'}. "
        f"Nominal parameters always fitted: {', '.join(report['nominal_parameters'])}.",
        "",
    ]
    if report.get("warnings"):
        lines += ["## Read first", ""] + [f"- {w}" for w in report["warnings"]] + [""]
    reg = report.get("global_registration")
    if reg and reg.get("applied"):
        lines += [
            (
                f"The recording was moved into the robot's base frame before the loop ({reg['reason']}): "
                f"rotation {reg['angle_deg']:.2f} deg (vector {np.round(reg['rotation_deg'], 3).tolist()} deg), "
                f"translation {np.round(reg['translation_mm'], 3).tolist()} mm; the nominal model's tip error "
                f"there {reg['rmse_mm']:.3f} mm, {reg['explained']:.1%} of the tip motion's variance explained. "
                "Positions and frame parameters below are in that frame; `measurement_frame` in report.json "
                "is the whole transform."
            ),
            "",
        ]
    return lines


def _md_before_after(report: dict) -> list[str]:
    nf = report["noise_floor_mm"]
    val = "rmse_validate_mm" in report
    lines: list[str] = []
    lines += [
        "## Before and after (tip-position RMSE, mm)",
        "",
        "| model | held out | / noise floor |" + (" validation | validation, mean offset removed |" if val else ""),
        "| --- | ---: | ---: |" + (" ---: | ---: |" if val else ""),
        f"| declared design, nothing fitted | {_f(report['rmse_declared_mm'])} | "
        f"{report['rmse_declared_mm'] / nf:.2f} |" + (" | |" if val else ""),
    ]
    for i, s in enumerate(report["steps"]):
        name = "nominal parameters fitted" if i == 0 else "+ " + " + ".join(s["effects"])
        lines.append(
            f"| {name} | {_f(s['rmse_held_out_mm'])} | {s['rmse_held_out_mm'] / nf:.2f} |"
            + (f" {_f(s['rmse_validate_mm'])} | {_f(s['rmse_validate_aligned_mm'])} |" if val else "")
        )
    lines += [
        f"| noise floor ({report['noise']['method']}, {report['noise']['pairs']} pairs) | {nf:.4f} | 1 |"
        + (" | |" if val else ""),
        "",
    ]
    fam = report["steps"][-1].get("rmse_by_family_mm") if report["steps"] else None
    if fam:
        lines += [
            "By pattern family (the final model; tip-position RMSE, mm):",
            "",
            "| part | family | RMSE |",
            "| --- | --- | ---: |",
        ]
        lines += [f"| {part} | {f} | {_f(v)} |" for part, rows in fam.items() for f, v in rows.items()]
        lines.append("")
    if val and report.get("baselines"):
        lines += [
            ("Black-box baselines (hyper-parameters chosen on the held-out part, refitted on all the training data):"),
            "",
            "| baseline | choice | held out | validation | validation aligned |",
            "| --- | --- | ---: | ---: | ---: |",
        ]
        for k, b in report["baselines"].items():
            lines.append(
                f"| {k} | {b['choice']} | {_f(b['rmse_held_out_mm'])} | {_f(b['rmse_validate_mm'])} | "
                f"{_f(b['rmse_validate_aligned_mm'])} |"
            )
        lines.append("")
    return lines


def _md_found(report: dict) -> list[str]:
    lines: list[str] = []
    lines += ["## What was found", ""]
    if report["effects"]:
        for e in report["effects"]:
            lines.append(f"- **{e['name']}**: {_fmt_params(e['params'], e.get('params_std'))}")
    else:
        lines.append("- No effect of the library improved the held-out error significantly: none added.")
    lines += [
        (
            f"- Unexplained structure left: **{'yes' if report['unexplained_structure'] else 'no'}** "
            f"(z > {STRUCTURE_Z:g} against an input, or RMSE > {EXCESS_RATIO} x noise floor)."
        ),
        "",
    ]
    if report["parameters"].get("at_bound"):
        lines += [
            (
                f"Parameters at a bound (their deviations are not meaningful): "
                f"{', '.join(report['parameters']['at_bound'])}."
            ),
            "",
        ]
    c = report["correlations"]
    if c["pairs"]:
        lines += [
            "Largest parameter correlations (Gauss-Newton; near 1 = a pair trades off freely): "
            + ", ".join(f"{p['a']} / {p['b']} {p['corr']:+.2f}" for p in c["pairs"])
            + ".",
            "",
        ]
    return lines


def _md_evidence(report: dict) -> list[str]:
    lines: list[str] = []
    lines += [
        "## Evidence",
        "",
        (
            "Score test on the held-out residual (z-value of the chi-square statistic of the residual "
            "projected on the effect's parameter sensitivities; higher = explains more), then the "
            "refit on the training part and the held-out check:"
        ),
        "",
    ]
    for rd in report["rounds"]:
        lines += _md_round(report, rd)
    return lines


def _verdict(t: dict, la: dict | None, jl: dict | None, nst: dict | None) -> str:
    """What the round decided on the refit ``t`` (its look-ahead, joint look and nested choice)."""
    verdict = "kept" if t["accepted"] else ("significant, not the best" if t["significant"] else "not significant")
    if t.get("short_of_share"):
        verdict = (
            f"significant, but {t['share_held_out']:.1%} of the held-out excess over the noise floor, "
            f"short of the {t['share_needed']:.1%} one effect needs"
            + (": the joint look goes on from it (below)" if jl and jl["first"] == t["name"] else "")
        )
    elif t["accepted"] and t.get("share_needed", 1.0) == 0.0:
        verdict = f"kept on the joint look ({t['share_held_out']:.1%} of the excess; no share of its own needed)"
    if la and not t["accepted"] and t["name"] == la["branches"][0]["first"]:
        verdict = "significant, the lowest, but its branch ended higher (look-ahead, below)"
    if nst and t["name"] == nst["over"]:
        verdict = f"significant, the lowest, but no significant drop over {nst['kept']} (below)"
    return verdict


def _md_round(report: dict, rd: dict) -> list[str]:
    """One round: its scores, short refits, refits and their verdicts, look-ahead, joint look and
    backward step."""
    lines: list[str] = []
    sc = [c for c in report["candidates"] if c["round"] == rd["round"]]
    lines.append(
        f"**Round {rd['round']}** (significant above z = {rd['z_critical']:.2f}): "
        + ", ".join(
            f"{c['name']} {c['score']:.1f}" if "not_scored" not in c else f"{c['name']} not scored ({c['not_scored']})"
            for c in sc
        )
        + "."
    )
    lines.append("")
    screened = [c for c in sc if "screened_rmse_mm" in c]
    if any(c.get("second_look") for c in sc):
        lines.append(
            "- no score significant, the held-out residual above the noise floor and not noise: a second "
            "look, short refits of the best-scoring candidates (a score is first order); one is "
            f"kept only if it explains at least {SECOND_LOOK_SHARE:.0%} of the excess"
        )
    if screened:
        lines.append(
            f"- short refits ({SCREEN_ITERATIONS} iterations; held-out RMSE before the round "
            f"{rd['rmse_held_out_mm']:.4f} mm): "
            + ", ".join(
                f"{c['name']} {c['screened_rmse_mm']:.4f} mm"
                + (" (too small a drop: no full refit)" if c.get("screened_out") else "")
                for c in screened
            )
        )
    la, jl, nst = rd.get("look_ahead"), rd.get("joint_look"), rd.get("nested")
    for t in rd["tried"]:
        verdict = _verdict(t, la, jl, nst)
        lines.append(
            f"- refit with {t['name']}: held-out RMSE {t['rmse_held_out_mm']:.4f} mm, drop of "
            f"the held-out sum of squares {t['sse_drop']:.1f} residual variances (needed "
            f"{t['needed']:.1f})"
            + (f", of the training part's {t['sse_drop_train']:.1f}" if "sse_drop_train" in t else "")
            + (
                f", of the later samples' {t['sse_drop_later']:.1f} (fitted on the earlier ones)"
                if "sse_drop_later" in t
                else ""
            )
            + f" -> {verdict}"
        )
    if nst:
        lines.append(
            f"- {nst['kept']} is a special case of {nst['over']}: {nst['over']}'s drop over it, "
            f"{nst['sse_drop']:.1f} residual variances, is short of the {nst['needed']:.1f} its "
            f"{nst['extra']} more parameters need -> **{nst['kept']}**"
        )
    if la:
        a, b = la["branches"]
        line = (
            f"- a near tie: the test could not tell {a['first']} from {b['first']}, and the loop ended with "
            f"structure left, so it went on from {b['first']} too (look-ahead): with {a['first']} first it ends "
            f"with {', '.join(a['effects']) or 'nothing'} at {a['rmse_held_out_mm']:.4f} mm held out; "
        )
        if "behind_after_round" in b:
            line += (
                f"with {b['first']} first it was behind after round {b['behind_after_round']} "
                f"({b['rmse_held_out_mm']:.4f} mm) and was given up"
            )
        else:
            line += (
                f"with {b['first']} first, with {', '.join(b['effects'])} at {b['rmse_held_out_mm']:.4f} mm "
                f"(drop {la['sse_drop']:.1f}, needed {la['needed']:.1f})"
            )
        lines.append(line + f" -> the branch of **{la['kept']}** is kept")
    if jl:
        lines.append(
            f"- nothing kept on its own, the loop far above the noise floor with structure left: a joint look went on "
            f"from {jl['first']} with refits that need no share of the excess of their own (every other test "
            f"stands). It adds {', '.join(jl['added']) or 'nothing'}"
            + (f" and removes {', '.join(jl['removed'])}" if jl["removed"] else "")
            + f": held-out RMSE {jl['rmse_held_out_mm']:.4f} mm, {jl['share_held_out']:.1%} of the excess "
            f"(needed {jl['share_needed']:.0%}), drop {jl['sse_drop']:.1f} (needed {jl['needed']:.1f}) -> "
            + ("**kept**" if jl["kept"] else "not kept")
        )
    for t in rd.get("removed", []):
        lines.append(
            f"- backward step: without {t['name']} the held-out RMSE is {t['rmse_held_out_mm']:.4f} mm "
            f"(rise {t['sse_rise']:.1f}, needed {t['needed']:.1f}): it only stood in for the new "
            "effect and is removed"
        )
    if not rd["tried"]:
        lines.append(
            "- no short refit lowered the held-out error: the loop stops."
            if screened
            else "- no candidate significant: the loop stops."
        )
    lines.append("")
    return lines


def _md_structure(report: dict) -> list[str]:
    lines: list[str] = []
    lines += [
        (
            "Structure left in the final held-out residual (k-NN smoother on one input at a time vs. "
            f"shuffled residuals; structure when z > {STRUCTURE_Z:g}):"
        ),
        "",
        "| input | variance explained | z |",
        "| --- | ---: | ---: |",
    ]
    for k, v in report["structure"].items():
        if "explained" in v:
            lines.append(f"| {k} | {v['explained']:.3f} | {v['z']:.1f} |")
    m = report["structure"]["mean"]
    ex = report["structure"]["excess_over_noise"]
    lines += [
        f"| mean offset {np.round(m['offset_mm'], 4).tolist()} mm | | {m['z']:.1f} |",
        f"| RMSE / noise floor = {ex['ratio_to_floor']:.3f} | | {ex['z']:.1f} |",
        "",
    ]
    return lines


def _md_parameters(report: dict) -> list[str]:
    lines: list[str] = []
    lines += [
        "## Final parameters",
        "",
        (
            "`physical`: the model's parameters after every fitted effect; `fitted`: each fitted block "
            "in report units (the refit on every sample); `std`: linearised standard deviations from that fit (optimistic: "
            "consecutive samples are correlated)."
        ),
        "",
        "```",
        json.dumps(report["parameters"], indent=1),
        "```",
        "",
        "## Plots",
        "",
    ]
    for f in report["plots"]:
        lines.append(f"![{f}]({f})")
    return lines


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items() if k != "predicted"}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return x


def write_report(res: Result, out_dir, **extra) -> dict:
    """Write ``report.json``, ``report.md`` and the plots into ``out_dir``; return the JSON dict.

    ``extra`` keys (e.g. ``design``, ``validate``: the files used) go into the report as they are.
    """
    out = Path(out_dir)
    report = res.to_json()
    report.update(extra)
    # every file is made in a hidden staging folder and moved in at the end: an interrupted run leaves
    # nothing that looks like a report (nor a plot that a rerun would refuse to overwrite)
    with staged_folder(out, last=("report.json", "report.md")) as stage:
        report["plots"] = [p.name for p in plot_residuals(res, stage)] + [plot_paths(res, stage).name]
        report = _jsonable(report)
        wires = res.problem.model.structure.n_wires_per_segment
        design = calibrated_design(report["parameters"], wires, "report.json")
        (stage / DESIGN_FILE).write_text(json.dumps(design, indent=1))
        (stage / "report.json").write_text(json.dumps(report, indent=1))
        (stage / "report.md").write_text(markdown(report))
    return report
