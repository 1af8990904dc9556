"""Writing a calibration's outcome: ``report.json``, ``report.md`` and the residual plots."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .diagnose import features
from .loop import STRUCTURE_Z, Result

PLOTS = {
    "bending_direction": "residual_vs_bending_direction.png",
    "motion": "residual_vs_motion.png",
}


def _components(res: Result, theta, feats):
    """Residual (N, 3) as radial (along the bending direction), tangential and axial parts."""
    r = res.problem.residuals(theta)
    c, s = np.cos(feats["bending_direction"]), np.sin(feats["bending_direction"])
    return np.stack([c * r[:, 0] + s * r[:, 1], -s * r[:, 0] + c * r[:, 1], r[:, 2]], axis=1)


def plot_residuals(res: Result, out_dir: Path) -> list[Path]:
    """Residual against bending direction and against direction of motion, before and after."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    pb = res.problem
    feats = features(pb.data, pb.predict(res.theta_declared))
    comps = {"before (nominal fit)": _components(res, res.theta_before, feats),
             "after (" + (", ".join(e["name"] for e in res.effects) or "no effect added") + ")":
                 _components(res, res.theta_after, feats)}
    lim = 1.1 * max(np.percentile(np.abs(c), 99.5) for c in comps.values())
    xlabels = {"bending_direction": "bending direction (deg, base frame)",
               "motion": "motion rel. to bending dir. (deg; 0 = bending further)"}
    paths = []
    for feat, fname in PLOTS.items():
        x = np.degrees(feats[feat])
        fig, axes = plt.subplots(2, 3, figsize=(13, 6.5), sharex=True, sharey=True)
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
        fig.suptitle(f"{Path(pb.data.source).name}: measured - predicted tip position "
                     f"(dashed: +-2 noise sigma)", fontsize=10)
        fig.tight_layout()
        path = out_dir / fname
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def _fmt_params(params: dict, std: dict | None = None) -> str:
    std = std or {}
    return ", ".join(f"{k} = {v:.4g}" + (f" +- {std[k]:.2g}" if k in std else "") for k, v in params.items())


def markdown(res: Result, report: dict) -> str:
    nf = report["noise_floor_mm"]
    lines = [f"# Calibration report: `{Path(report['data']).name}`", ""]
    lines += [f"{report['n_samples']} samples ({report['dropped_rows']} bad rows dropped); training: the first "
              f"{report['n_train']} in acquisition order, held out: the last {report['n_held_out']}. "
              f"Loss: {'Huber (robust)' if report['robust'] else 'least squares'}. "
              f"Nominal parameters always fitted: {', '.join(report['nominal_parameters'])}.", ""]
    lines += ["## Before and after (held-out tip-position RMSE)", "",
              "| model | RMSE (mm) | / noise floor |", "| --- | ---: | ---: |",
              f"| declared design, nothing fitted | {report['rmse_declared_mm']:.4f} | "
              f"{report['rmse_declared_mm'] / nf:.2f} |",
              f"| nominal parameters fitted | {report['rmse_before_mm']:.4f} | "
              f"{report['rmse_before_mm'] / nf:.2f} |"]
    acc = []
    for e in report["effects"]:
        acc.append(e["name"])
        lines.append(f"| + {' + '.join(acc)} | {e['rmse_after_mm']:.4f} | {e['rmse_after_mm'] / nf:.2f} |")
    lines += [f"| **final** | **{report['rmse_after_mm']:.4f}** | **{report['rmse_after_mm'] / nf:.2f}** |",
              f"| noise floor ({report['noise']['method']}, {report['noise']['pairs']} pairs) | {nf:.4f} | 1 |",
              ""]
    lines += ["## What was found", ""]
    if report["effects"]:
        for e in report["effects"]:
            lines.append(f"- **{e['name']}**: {_fmt_params(e['params'], e.get('params_std'))}")
    else:
        lines.append("- No effect of the library improved the held-out error significantly: none added.")
    lines += [f"- Unexplained structure left: **{'yes' if report['unexplained_structure'] else 'no'}**.", ""]
    lines += ["## Evidence", "",
              "Score test on the held-out residual (z-value of the chi-square statistic of the residual "
              "projected on the effect's parameter sensitivities; higher = explains more), then the "
              "refit on the training part and the held-out check:", ""]
    for rd in report["rounds"]:
        sc = [c for c in report["candidates"] if c["round"] == rd["round"]]
        lines.append(f"**Round {rd['round']}** (significant above z = {rd['z_critical']:.2f}): "
                     + ", ".join(f"{c['name']} {c['score']:.1f}" for c in sc) + ".")
        lines.append("")
        for t in rd["tried"]:
            verdict = "kept" if t["accepted"] else ("significant, not the best" if t["significant"]
                                                    else "not significant")
            lines.append(f"- refit with {t['name']}: held-out RMSE {t['rmse_held_out_mm']:.4f} mm, drop of "
                         f"the held-out sum of squares {t['sse_drop']:.1f} residual variances (needed "
                         f"{t['needed']:.1f}) -> {verdict}")
        for t in rd.get("removed", []):
            lines.append(f"- backward step: without {t['name']} the held-out RMSE is {t['rmse_held_out_mm']:.4f} mm "
                         f"(rise {t['sse_rise']:.1f}, needed {t['needed']:.1f}): it only stood in for the new "
                         "effect and is removed")
        if not rd["tried"]:
            lines.append("- no candidate significant: the loop stops.")
        lines.append("")
    lines += ["Structure left in the final held-out residual (k-NN smoother on one input at a time vs. "
              f"shuffled residuals; structure when z > {STRUCTURE_Z:g}):", "",
              "| input | variance explained | z |", "| --- | ---: | ---: |"]
    for k, v in report["structure"].items():
        if "explained" in v:
            lines.append(f"| {k} | {v['explained']:.3f} | {v['z']:.1f} |")
    m = report["structure"]["mean"]
    ex = report["structure"]["excess_over_noise"]
    lines += [f"| mean offset {np.round(m['offset_mm'], 4).tolist()} mm | | {m['z']:.1f} |",
              f"| RMSE / noise floor = {ex['ratio_to_floor']:.3f} | | {ex['z']:.1f} |", ""]
    lines += ["## Final parameters", "",
              "`physical`: the model's parameters after every fitted effect; `fitted`: each fitted block "
              "in report units; `std`: linearised standard deviations from the training fit.", "", "```", json.dumps(report["parameters"], indent=1), "```", "",
              "## Plots", ""]
    for f in PLOTS.values():
        lines.append(f"![{f}]({f})")
    return "\n".join(lines) + "\n"


def write_report(res: Result, out_dir) -> dict:
    """Write ``report.json``, ``report.md`` and the plots into ``out_dir``; return the JSON dict."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = res.to_json()
    report["plots"] = [p.name for p in plot_residuals(res, out)]
    (out / "report.json").write_text(json.dumps(report, indent=1))
    (out / "report.md").write_text(markdown(res, report))
    return report
