"""What a user must know about a calibration before trusting it, one line each.

* **Knife edges**: a decision of the loop whose statistic fell within ``KNIFE_EDGE`` (relative) of its
  threshold. The same robot recorded again could fall on the other side, and give another model: the
  report says which decision, by how much, and what the other side would have given.
* **Parameters at a bound**: the data ask for more than the effect's range allows (e.g. a backbone EI
  twenty times the declared one): the design file's value, or the model, is likely wrong there.
* **The frame**: a global registration that leaves the nominal model far from the measurements.
"""

from __future__ import annotations

import numpy as np

#: A decision whose statistic is within this fraction of its threshold is reported as a knife edge.
KNIFE_EDGE = 0.05


def _near(value, threshold) -> bool:
    return threshold > 0 and abs(value - threshold) <= KNIFE_EDGE * threshold


def knife_edges(rounds: list) -> list[dict]:
    """The loop's decisions (``report["rounds"]``) that fell within :data:`KNIFE_EDGE` of a threshold:
    ``{"round", "what", "test", "value", "threshold", "decided", "other_side_rmse_mm", "other_side_at"}``,
    where ``other_side_rmse_mm`` is the held-out RMSE the other decision would have given, and
    ``other_side_at`` where: ``"round"``, at that round (a refit's; the rounds after it are not run
    for the other side), or ``"end"``, the whole loop's (a joint look's or a look-ahead's)."""
    return [e for rd in rounds for kind in (_refit_edges, _joint_edges, _nested_edges, _ahead_edges) for e in kind(rd)]


def _edge(rd: dict, what: str, test: str, value, threshold, decided: str, other, at: str) -> dict:
    return {
        "round": rd["round"],
        "what": what,
        "test": test,
        "value": float(value),
        "threshold": float(threshold),
        "decided": decided,
        "other_side_rmse_mm": float(other),
        "other_side_at": at,
    }


def _refit_edges(rd: dict) -> list[dict]:
    """A round's refits whose tests fell near their thresholds, where crossing one changes the model."""
    out = []
    best = min((t["rmse_held_out_mm"] for t in rd["tried"] if t["accepted"]), default=np.inf)
    for t in rd["tried"]:
        if not t["accepted"] and (t["significant"] or t["rmse_held_out_mm"] >= best):
            continue  # a better refit was kept: crossing this one's edge changes nothing
        kept = bool(t["accepted"])
        other = rd["rmse_held_out_mm"] if kept else t["rmse_held_out_mm"]
        tests = [
            ("held-out drop", t["sse_drop"], t["needed"]),
            ("training drop", t.get("sse_drop_train", np.inf), t["needed"]),
            ("later samples' drop", t.get("sse_drop_later", np.inf), t["needed"]),
            ("share of the excess", t.get("share_held_out", 0.0), t.get("share_needed", 0.0)),
        ]
        for test, value, threshold in tests:
            # an edge decides only where the refit's other tests passed (or it was kept)
            if _near(value, threshold) and (kept or t.get("short_of_share") or test != "share of the excess"):
                decided = "kept" if kept else "not kept"
                out.append(_edge(rd, f"refit with {t['name']}", test, value, threshold, decided, other, "round"))
    return out


def _joint_edges(rd: dict) -> list[dict]:
    jl = rd.get("joint_look")
    if not jl:
        return []
    what, decided = "joint look (" + " + ".join(jl["added"]) + ")", "kept" if jl["kept"] else "not kept"
    other = jl.get("rmse_before_mm", np.nan) if jl["kept"] else jl["rmse_held_out_mm"]
    return [
        _edge(rd, what, test, value, threshold, decided, other, "end")
        for test, value, threshold in (
            ("share of the excess", jl["share_held_out"], jl["share_needed"]),
            ("held-out drop", jl["sse_drop"], jl["needed"]),
        )
        if _near(value, threshold)
    ]


def _nested_edges(rd: dict) -> list[dict]:
    nst = rd.get("nested")
    if not nst or not _near(nst["sse_drop"], nst["needed"]):
        return []
    over = next(t for t in rd["tried"] if t["name"] == nst["over"])
    what = f"{nst['kept']} as a special case of {nst['over']}"
    decided = f"{nst['kept']} kept"
    return [
        _edge(rd, what, "drop of the larger over it", nst["sse_drop"], nst["needed"], decided,
              over["rmse_held_out_mm"], "round")
    ]  # fmt: skip


def _ahead_edges(rd: dict) -> list[dict]:
    la = rd.get("look_ahead")
    if not la or "sse_drop" not in la or not _near(la["sse_drop"], la["needed"]):
        return []
    a, b = la["branches"]
    other = (b if la["kept"] == a["first"] else a)["rmse_held_out_mm"]
    what = f"look-ahead ({a['first']} or {b['first']} first)"
    return [_edge(rd, what, "held-out drop", la["sse_drop"], la["needed"], f"{la['kept']} first", other, "end")]


def _edge_line(e: dict) -> str:
    return (
        f"knife edge in round {e['round']}: {e['what']}, {e['test']} {e['value']:.4g} against "
        f"{e['threshold']:.4g} needed ({e['decided']}; the other side"
        f"{', at that round' if e.get('other_side_at') == 'round' else ''}: held out "
        f"{e['other_side_rmse_mm']:.3f} mm)"
    )


def bound_lines(at_bound: list, fitted: dict, declared: dict) -> list[str]:
    """One line per parameter at a bound (labels ``block.label``), with its value and the declared one."""
    out = []
    for lab in at_bound:
        block, name = lab.split(".", 1)
        v, d = fitted.get(block, {}).get(name), declared.get(block, {}).get(name)
        if v is None:
            out.append(f"{lab} at its bound")
            continue
        ratio = f", {v / d:.3g}x the declared {d:.4g}" if d not in (None, 0.0) and block == "backbone_EI" else ""
        hint = ": check the design file's value" if block == "backbone_EI" else ": the data ask for more than its range"
        out.append(f"{lab} at its bound ({v:.4g}{ratio}){hint}")
    return out


def caveats(report: dict) -> list[str]:
    """Every caveat of a report (``report.json``'s content), one line each."""
    lines = [_edge_line(e) for e in report.get("knife_edges", [])]
    lines += report.get("bound_warnings", [])
    reg = report.get("global_registration")
    if reg and reg.get("applied") and not reg.get("trusted", True):
        lines.append(f"global registration doubtful: {reg['reason']}")
    return lines
