"""The ``tension-zones`` command line: a thin shell around the library.

Errors are one line on stderr (``tension-zones: error: ...``) and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

import numpy as np

from ._xla import COMPILE_THREAD

# Only the standard library and NumPy at import (and ``_xla``, which imports no JAX):
# `tension-zones --help` and `CMD --help` never import JAX (each command imports what it needs when
# it runs).


class CLIError(Exception):
    """A user-facing error: printed as one line."""


#: The largest wire count the command line takes (the library takes any): the measures cost n^2 per
#: pose above 8 wires, so 256 wires sweep the default grid in seconds and far more would not.
MAX_WIRES = 256
#: The largest sweep grid the command line takes: 10^7 poses hold 1.4 GB of kinematic results.
MAX_SWEEP_POSES = 20_000_000
#: Design fields -> the flags that set them (a design error names the flag).
_FLAG_OF_FIELD = {
    "n_wires": "--wires",
    "length": "--length",
    "pitch_radius": "--pitch-radius",
    "wire_angles": "--angles",
    "wire_angles_deg": "--angles",
    "wire_stiffness": "--wire-stiffness",
    "backbone_EI": "--backbone-EI",
    "preload": "--preload",
}


def _design_error(e: ValueError) -> CLIError:
    """A design's one-line ValueError, prefixed with the flag of the field it names."""
    flag = _FLAG_OF_FIELD.get(str(e).split(" ", 1)[0])
    return CLIError(f"{flag}: {e}" if flag else str(e))


def _parse_angles(text: str | None, n_wires: int | None):
    """``--angles`` in degrees (a list), checked for count and finiteness."""
    if text is None:
        return None
    try:
        vals = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise CLIError(f"--angles must be comma-separated numbers in degrees, got {text!r}") from None
    if n_wires is not None and len(vals) != n_wires:
        raise CLIError(f"--angles has {len(vals)} values but --wires is {n_wires}")
    if not np.all(np.isfinite(vals)):
        raise CLIError(f"--angles must be finite numbers in degrees, got {text!r}")
    return vals


def _design(args, length=20.0, pitch_radius=2.0):
    from .model._design import Design, _check_angles

    if args.wires > MAX_WIRES:
        raise CLIError(
            f"--wires must be at most {MAX_WIRES} on the command line, got {args.wires} "
            "(tension_zones.Design takes any count)"
        )
    angles = _parse_angles(getattr(args, "angles", None), args.wires)
    try:
        if angles is not None:
            _check_angles(angles, args.wires, field="wire_angles_deg")  # its message in degrees
        return Design(args.wires, length, pitch_radius, wire_angles=None if angles is None else np.radians(angles))
    except ValueError as e:
        raise _design_error(e) from None


# ---- output paths: checked before any computation, never overwritten without --force -----------
def _probe_writable(folder: Path, flag: str) -> None:
    """Create and remove a file in ``folder``: the one test that also catches read-only file systems
    and permissions that ``os.access`` misreports."""
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tension-zones-probe-")
    except OSError as e:
        raise CLIError(
            f"{flag}: cannot write in the folder {str(folder)!r} ({e.strerror or type(e).__name__})"
        ) from None
    os.close(fd)
    os.unlink(tmp)


def _check_out_file(path: str, suffix: str, force: bool = False, flag: str = "--out") -> Path:
    """An output file ``path``: ends in ``suffix``, is not a folder, its folder exists and is
    writable, and it does not exist yet unless ``force``. Returns it as a ``Path``."""
    p = Path(path)
    if p.suffix.lower() != suffix:
        raise CLIError(f"{flag} must end in {suffix}, got {path!r}")
    if p.is_dir():
        raise CLIError(f"{flag} must be a file, {path!r} is a folder")
    if not p.parent.exists():
        raise CLIError(f"the folder of {flag} does not exist: {str(p.parent)!r}")
    if not p.parent.is_dir():
        raise CLIError(f"the folder of {flag} is a file: {str(p.parent)!r}")
    if p.exists() and not force:
        raise CLIError(f"{flag} {path!r} exists; pass --force to overwrite it, or choose another name")
    _probe_writable(p.parent, flag)
    return p


def _check_out_dir(path: str, force: bool = False, names=None, flag: str = "--out") -> Path:
    """An output folder ``path``: not a file; it exists and is writable, or its parent does (it is
    created when the results are written). Without ``force`` it may not already hold any of
    ``names`` (the files the command writes), or anything at all when ``names`` is None."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise CLIError(f"{flag} must be a folder, {path!r} is a file")
    if out.is_dir():
        held = (
            sorted(n for n in names if (out / n).exists())
            if names is not None
            else sorted(p.name for p in out.iterdir())
        )
        if held and not force:
            more = f" and {len(held) - 1} more" if len(held) > 1 else ""
            raise CLIError(
                f"{flag} {path!r} already holds {held[0]!r}{more}; pass --force to overwrite, or choose another folder"
            )
        _probe_writable(out, flag)
    else:
        if not out.parent.is_dir():
            raise CLIError(f"the folder of {flag} does not exist: {str(out.parent)!r}")
        _probe_writable(out.parent, flag)
    return out


def cmd_maps(args) -> None:
    from .model import Design

    out = _check_out_file(args.out, ".png", args.force)
    design = _subject(args, "maps", needs=("wires",))
    if not isinstance(design, Design):
        return _robot_maps(args, design, out)
    if args.bend is not None:
        raise CLIError("--bend is the other segments' bending in a robot's maps; a segment has none")

    import matplotlib.pyplot as plt

    from ._io import atomic_path
    from .model._zones import tension_map
    from .plots import plot_tension_map

    tmap = tension_map(design)
    fig, ax = plt.subplots(figsize=(6.4, 6.8))
    plot_tension_map(tmap, ax=ax)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=130, bbox_inches="tight")
    plt.close(fig)
    print(tmap.table())
    if not args.quiet:
        print(f"wrote {out}")


def _robot_maps(args, robot, out) -> None:
    """``maps`` of a robot: each segment's tension map with the others straight and still, and with
    the others bent ``--bend`` deg (towards delta = 0) and bending further: how they move its zones."""
    from ._io import atomic_path
    from .model._chain_zones import crossing_wires, segment_tension_map
    from .plots import plot_segment_maps

    bend = 45.0 if args.bend is None else args.bend
    if not (np.isfinite(bend) and 0 < bend <= 180):
        raise CLIError(f"--bend must be a bending angle in (0, 180] degrees, got {bend:g}")
    S = robot.n_segments
    rows = []
    for label, phi in (("the others straight and still", 0.0), (f"the others bent {bend:g} deg towards 0 deg", bend)):
        maps = []
        for j in range(S):
            B = np.zeros((S, 2))
            B[:, 0] = np.radians(phi)
            B[j] = 0.0
            maps.append(segment_tension_map(robot, j, B))
        rows.append((label, maps))
    fig = plot_segment_maps(rows, [crossing_wires(robot, j) for j in range(S)])
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    for label, maps in rows:
        for j, tmap in enumerate(maps):
            wires = crossing_wires(robot, j)
            print(f"segment {j + 1} of {S}, {label} (map wire k is robot wire {wires[0]} + k - 1):")
            print(tmap.table())
    if not args.quiet:
        print(f"wrote {out}")


def cmd_reproduce(args) -> None:
    out = _check_out_dir(args.out, args.force)
    from .paper._reproduce import reproduce

    reproduce(out, quiet=args.quiet)


# --- optimize -----------------------------------------------------------------------
def _numbers(values) -> str:
    """Per-segment numbers, comma-separated."""
    return ", ".join(f"{v:.4g}" for v in values)


def _optimize_start(args):
    """``optimize --design FILE``: the robot the search starts from and its calibrated play of each wire
    (None where the file has none); ``(None, None)`` without the flag."""
    from .model import Robot, read_json

    if args.design is None:
        return None, None
    try:
        robot = Robot.from_json(args.design)
        play = Robot.calibrated_block(read_json(args.design, "design file")).get("wire_play_mm")
    except ValueError as e:
        raise CLIError(str(e)) from None
    return robot, play


def cmd_optimize(args) -> None:
    from .design._optimise import optimize, wires_label
    from .design._scenario import load_scenario
    from .plots import OUTPUT_FILES, write_outputs

    start, play = _optimize_start(args)
    try:
        sc = load_scenario(args.scenario, start, play)
    except ValueError as e:
        raise CLIError(str(e)) from None
    out = _check_out_dir(args.out, args.force, OUTPUT_FILES)
    result = optimize(sc, progress=not args.quiet, start=start)
    paths = write_outputs(result, out)
    best = result["best"]
    if start is not None:
        s = result["start"]
        print(
            f"start ({args.design}): objective {s['objective']:.4g}, worst position uncertainty "
            f"{s['worst_position_uncertainty_mm']:.4g} mm" + ("" if s["feasible"] else " (infeasible)")
        )
    if best is None:
        print("no feasible design: see result.json for each wire count's violations")
    elif "design" in best:  # several segments: per segment, proximal first
        print(
            f"best: {wires_label(best['n_wires'])} wires, r = {_numbers(best['pitch_radius_mm'])} mm, "
            f"k_w = {_numbers(best['wire_stiffness_N_per_mm'])} N/mm, preload = {_numbers(best['preload_N'])} N, "
            f"objective {best['objective']:.4g}"
        )
    else:
        print(
            f"best: {best['n_wires']} wires, r = {best['pitch_radius_mm']:.4g} mm, "
            f"k_w = {best['wire_stiffness_N_per_mm']:.4g} N/mm, angles = "
            f"{', '.join(f'{a:.1f}' for a in best['wire_angles_deg'])} deg, "
            f"objective {best['objective']:.4g}"
        )
    if not args.quiet:
        for p in paths:
            print(f"wrote {p}")


# ---- sweep: workspace performance maps ------------------------------------------------
def _kinematics_measure(args):
    """tension_zones/MODEL.md Sec. 3 measures, full and reduced: ``(per-pose function, extra args)``."""
    from .analysis._metrics import pose_metrics

    return pose_metrics, (args.dq,)


#: Per-pose measures ``tension-zones sweep --measure`` can sweep: name -> builder(args) returning
#: ``(fn(design, theta_L, delta, *extra) -> dict, extra)``. Another measure is one more entry.
SWEEP_MEASURES = {"kinematics": _kinematics_measure}


def _positive(name: str, value: float) -> float:
    if not (np.isfinite(value) and value > 0):
        raise CLIError(f"{name} must be a positive number, got {value:g}")
    return value


def _load_arg(text: str) -> np.ndarray:
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise CLIError(f"--load must be FX,FY,FZ (or six wrench components) in N, got {text!r}") from None
    if len(vals) not in (3, 6) or not np.all(np.isfinite(vals)):
        raise CLIError(f"--load must be 3 finite forces FX,FY,FZ (N) or 6 wrench components, got {text!r}")
    return np.asarray(vals)


def _with_compliance(args):
    """Kinematic measures plus the tension-only statics in one per-pose function."""
    from .analysis._metrics import pose_metrics
    from .model._statics import as_wrench, compliance_pose

    wrench = as_wrench(_load_arg(args.load))

    def fn(design, theta_L, delta, dq, w):
        return {**pose_metrics(design, theta_L, delta, dq), **compliance_pose(design, theta_L, delta, w)}

    return fn, (args.dq, wrench)


def cmd_sweep(args) -> None:
    from .analysis import DEFAULT_DQ
    from .analysis._sweep import grid_deg, grid_size, sweep_grid
    from .model import Design
    from .model._statics import PAPER_DELTA_DEG, PAPER_THETA_L_DEG

    out = _check_out_file(args.out, ".npz", args.force)
    subject = _sweep_subject(args)
    if args.dq is None:
        args.dq = DEFAULT_DQ
    _check_compliance_flags(args)
    if not isinstance(subject, Design):
        return _sweep_robot(args, subject, out)
    if args.samples is not None or args.max_bend is not None:
        raise CLIError(
            "--samples and --max-bend sample a robot of several segments; a segment sweeps the "
            "theta_L x delta grid (--theta-step, --delta-step)"
        )
    design = subject
    if args.compliance and args.design is None:
        try:
            design = design.replace(
                wire_stiffness=args.wire_stiffness, backbone_EI=args.backbone_EI, preload=args.preload or 0.0
            )
        except ValueError as e:
            raise _design_error(e) from None
    for name in ("theta_step", "delta_step", "dq"):
        if getattr(args, name) is not None:
            _positive("--" + name.replace("_", "-"), getattr(args, name))
    steps = (args.theta_step or 5.0, args.delta_step or 2.5)
    for flag, step, span in (("--theta-step", steps[0], 85.0), ("--delta-step", steps[1], 360.0)):
        if step > span:  # a grid of its start alone
            raise CLIError(
                f"{flag} {step:g} leaves {grid_size(span, step)} grid point on 0..{span:g} deg; "
                f"it must be at most {span:g}"
            )
    size = grid_size(85.0, steps[0]) * grid_size(360.0, steps[1])
    if size > MAX_SWEEP_POSES:  # checked before the grid is built
        raise CLIError(
            f"--theta-step {steps[0]:g} and --delta-step {steps[1]:g} make {size:,} "
            f"poses; the command line sweeps at most {MAX_SWEEP_POSES:,} (sweep_grid "
            "from Python takes more)"
        )
    if args.compliance and args.theta_step is None:
        theta_deg = np.asarray(PAPER_THETA_L_DEG)  # the paper's Sec. 6.2 grid
    else:
        theta_deg = grid_deg(85.0, steps[0])  # Sec. 6.1: 0..85 deg, ends included
    if args.compliance and args.delta_step is None:
        delta_deg = np.asarray(PAPER_DELTA_DEG)
    else:
        delta_deg = grid_deg(360.0, steps[1])
    fn, extra = _with_compliance(args) if args.compliance else SWEEP_MEASURES[args.measure](args)
    res = sweep_grid(
        fn,
        design,
        np.radians(theta_deg),
        np.radians(delta_deg),
        *extra,
        quiet=args.quiet,
        desc="sweep" + (" + compliance" if args.compliance else ""),
    )
    th, de = np.meshgrid(theta_deg, delta_deg, indexing="ij")
    from ._io import atomic_path

    with atomic_path(out) as tmp:
        np.savez(tmp, theta_L_deg=th, delta_deg=de, **res)  # type: ignore[arg-type]
    if not args.quiet:
        print(f"wrote {out}: {th.shape[0]} x {th.shape[1]} poses, {len(res) + 2} arrays")
        if args.compliance and not np.all(res["feasible"]):
            print(
                f"note: {int(np.sum(~res['feasible']))} poses cannot be held without pushing "
                "(feasible = False, deflections NaN there)"
            )


def _subject(args, command: str, needs=("wires", "length", "pitch_radius")):
    """The segment (``--wires`` and the other flags in ``needs``, or a one-segment ``--design`` file) or
    the robot (a ``--design`` file of several segments) a command works on."""
    from .model import Robot

    given = [f for f in ("wires", "length", "pitch_radius", "angles") if getattr(args, f, None) is not None]
    if args.design is not None:
        if given:
            flags = ", ".join("--" + f.replace("_", "-") for f in given)
            raise CLIError(f"{flags}: the --design file sets the robot; give one or the other")
        try:
            robot = Robot.from_json(args.design)
        except ValueError as e:
            raise CLIError(str(e)) from None
        return robot.segments[0] if robot.n_segments == 1 else robot
    missing = [f for f in needs if getattr(args, f) is None]
    if missing:
        raise CLIError(
            f"{command} needs --design FILE, or "
            + ", ".join("--" + f.replace("_", "-") for f in missing)
            + " for one segment"
        )
    length, radius = getattr(args, "length", None), getattr(args, "pitch_radius", None)
    return _design(args, length=20.0 if length is None else length, pitch_radius=2.0 if radius is None else radius)


def _check_compliance_flags(args) -> None:
    """``--compliance`` needs a load, and the stiffnesses from the flags (``--wires``) or the file
    (``--design``, which then sets them); the statics flags go with it only."""
    stiff = ("wire_stiffness", "backbone_EI", "preload")
    if not args.compliance:
        if any(getattr(args, f) is not None for f in (*stiff, "load")):
            raise CLIError("--wire-stiffness, --backbone-EI, --load and --preload go with --compliance")
        return
    if args.design is not None:
        given = [f for f in stiff if getattr(args, f) is not None]
        if given:
            flags = ", ".join("--" + f.replace("_", "-") for f in given)
            raise CLIError(f"{flags}: the --design file sets the robot's stiffness and preload")
    needed = ("load",) if args.design is not None else ("wire_stiffness", "backbone_EI", "load")
    missing = [f for f in needed if getattr(args, f) is None]
    if missing:
        raise CLIError("--compliance needs " + ", ".join("--" + m.replace("_", "-") for m in missing))


def _sweep_subject(args):
    """:func:`_subject` for ``sweep``; a calibrated design file's play of each wire becomes ``--dq``
    unless it is given."""
    from .model import Design, Robot, read_json

    subject = _subject(args, "sweep")
    if args.design is None:
        return subject
    play = Robot.calibrated_block(read_json(args.design, "design file")).get("wire_play_mm")
    if args.dq is None and play is not None and max(play) > 0:
        args.dq = np.asarray(play, float) if not isinstance(subject, Design) else max(play)
        if not args.quiet:
            print(f"dq: the calibrated play of each wire ({', '.join(f'{p:.3g}' for p in play)} mm)")
    return subject


#: Configurations a robot's sweep samples unless ``--samples`` says otherwise.
DEFAULT_SAMPLES = 1 << 16


def _robot_with_compliance(robot, B, dq, wrench):
    """A robot's kinematic measures and its tension-only statics in one per-configuration function."""
    from .analysis import config_metrics
    from .model import config_compliance

    return {**config_metrics(robot, B, dq), **config_compliance(robot, B, wrench)}


def _sweep_robot(args, robot, out) -> None:
    """``sweep`` of a robot of several segments: its kinematic measures, full and reduced
    (:func:`~tension_zones.analysis.config_metrics`), on Halton samples of its configurations."""
    from ._io import atomic_path
    from .analysis import config_metrics, config_samples, sweep_configs
    from .model._statics import as_wrench

    S = robot.n_segments
    if args.theta_step is not None or args.delta_step is not None:
        raise CLIError(
            f"--theta-step and --delta-step are one segment's grid; a robot of {S} segments takes "
            "--samples and --max-bend"
        )
    n = DEFAULT_SAMPLES if args.samples is None else args.samples
    if not 1 <= n <= MAX_SWEEP_POSES:
        raise CLIError(f"--samples must be 1 to {MAX_SWEEP_POSES:,}, got {n:,}")
    max_bend = 90.0 if args.max_bend is None else args.max_bend
    if not (np.isfinite(max_bend) and 0 < max_bend <= 180):
        raise CLIError(f"--max-bend must be a bending angle in (0, 180] degrees, got {max_bend:g}")
    if np.ndim(args.dq) == 0:  # (a calibrated file's play per wire is checked when it is read)
        _positive("--dq", args.dq)
    B = config_samples(S, n, max_bend)
    fn: Callable = config_metrics
    extra: tuple = (args.dq,)
    if args.compliance:
        fn, extra = _robot_with_compliance, (args.dq, as_wrench(_load_arg(args.load)))
    res = sweep_configs(fn, robot, B, *extra, quiet=args.quiet, desc=f"sweep ({S} segments)")
    with atomic_path(out) as tmp:
        np.savez(tmp, B=B, bend_deg=np.degrees(np.linalg.norm(B, axis=-1)), **res)  # type: ignore[arg-type]
    if not args.quiet:
        print(
            f"wrote {out}: {n:,} configurations of {S} segments (Halton, |b_j| <= {max_bend:g} deg), {len(res) + 2} arrays"
        )


def _add_sweep_parser(sub) -> None:
    s = sub.add_parser("sweep", help="sweep performance measures over the workspace into a .npz")
    s.add_argument(
        "--design",
        help="a design file (.design.json): one segment, or a robot of several (swept on --samples configurations)",
    )
    s.add_argument("--wires", type=int, help="number of wires (>= 3), without --design")
    s.add_argument("--length", type=float, help="segment length L (mm), without --design")
    s.add_argument("--pitch-radius", type=float, help="wire pitch radius r (mm), without --design")
    s.add_argument("--angles", help="wire angles in degrees, comma-separated (default: even), without --design")
    s.add_argument(
        "--theta-step",
        type=float,
        default=None,
        help="theta_L step (deg), 0..85 (default 5; with --compliance the paper's Sec. 6.2 grid linspace(89, 45, 10))",
    )
    s.add_argument(
        "--delta-step", type=float, default=None, help="delta step (deg), 0..360 (default 2.5; with --compliance 15)"
    )
    s.add_argument(
        "--dq",
        type=float,
        help="joint uncertainty bound (mm, default 0.4; a calibrated design file's play of each wire)",
    )
    s.add_argument(
        "--samples",
        type=int,
        help=f"a robot of several segments: configurations to sweep, Halton (default {DEFAULT_SAMPLES})",
    )
    s.add_argument(
        "--max-bend",
        type=float,
        help="a robot of several segments: largest bending angle of each segment (deg, default 90)",
    )
    s.add_argument(
        "--measure",
        choices=sorted(SWEEP_MEASURES),
        default="kinematics",
        help="which per-pose measures to sweep (default: kinematics)",
    )
    c = s.add_argument_group("compliance: tension-only statics")
    c.add_argument(
        "--compliance",
        action="store_true",
        help="add deflection_mm_MODE, deflection_deg_MODE, tensions, n_taut_statics, feasible "
        "(a --design file gives the stiffnesses and preload)",
    )
    c.add_argument("--wire-stiffness", type=float, help="k_w (N/mm)")
    c.add_argument("--backbone-EI", type=float, help="backbone bending stiffness EI (N mm^2)")
    c.add_argument("--load", help="tip force FX,FY,FZ (N, base frame), or six wrench components")
    c.add_argument("--preload", type=float, help="wire preload f_min (N, default 0)")
    s.add_argument("--out", required=True, help="output .npz file")
    _add_force(s, "an existing --out file")
    s.add_argument("--quiet", action="store_true", help="no progress bar or messages")
    s.set_defaults(func=cmd_sweep)


# ---- end sweep -----------------------------------------------------------------------


# ---- calibrate ---------------------------------------------------------------------------------
def cmd_calibrate(args) -> None:
    """Fit a robot (one segment or many) to tracker data, trace the residual to effects, report."""
    import warnings

    from .calibration import DataError, calibrate, load_data, write_report
    from .calibration._report import FILES
    from .calibration.effects import BY_NAME, OPT_IN
    from .calibration.effects import library as default_library
    from .model import Robot

    if args.workers is not None and args.workers < 0:
        raise CLIError(f"--workers must be 0 or more, got {args.workers}")
    out = _out_dir(args.out, FILES, args.force)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            robot = Robot.from_json(args.design, warn_missing=True)
        for w in caught:
            print(f"tension-zones: warning: {w.message}", file=sys.stderr)
        kw = {"n_wires": robot.n_wires, "drop_bad": args.drop_bad}
        if args.format == "model":
            kw["length"] = float(robot.lengths.sum())
        data = load_data(args.data, args.format, **kw)
        val = None
        if args.validate is not None:
            if args.format == "opencr":
                kw["servo_ids"] = data.servo_ids  # the training file's servo map
            val = load_data(args.validate, args.format, **kw)
        library = None
        if args.effects is not None:
            names = [e.strip() for e in args.effects.split(",") if e.strip()]
            extra = [n[1:].strip() for n in names if n.startswith("+")]  # added to the default library
            known = [e.name for e in default_library(data.frame, OPT_IN)]
            unknown = [n for n in [n.lstrip("+").strip() for n in names] if n not in known]
            if unknown:
                raise CLIError(
                    f"--effects: unknown effect {unknown[0]!r}; candidates for these data: {', '.join(known)}"
                )
            if extra and len(extra) < len(names):
                raise CLIError(
                    "--effects: either a list of effects or +NAME additions to the default library, not both"
                )
            library = (
                default_library(data.frame, [n for n in extra if n in OPT_IN])
                if extra
                else tuple(BY_NAME[n] for n in names)
            )
        data, val, first = _calibration_size(args, data, val, robot.n_segments)

        def say(line):  # the estimate first, once the calibration has checked its inputs
            while first:
                print(first.pop(), file=sys.stderr)
            print(line, file=sys.stderr)

        res = calibrate(
            data,
            robot,
            validate=val,
            library=library,
            holdout=0.25 if args.holdout is None else args.holdout,
            robust=args.robust,
            log=None if args.quiet else say,
            workers=args.workers,
        )
    except DataError as e:
        raise CLIError(str(e)) from None
    report = write_report(res, out, design=str(args.design), validate=args.validate)
    found = ", ".join(e["name"] for e in report["effects"]) or "none"
    line = (
        f"held-out RMSE: declared {report['rmse_declared_mm']:.4f} mm, nominal fit "
        f"{report['rmse_before_mm']:.4f} mm, after {report['rmse_after_mm']:.4f} mm "
        f"(noise floor {report['noise_floor_mm']:.4f} mm); effects added: {found}; "
        f"unexplained structure: {'yes' if report['unexplained_structure'] else 'no'}; "
        f"dropped rows: {report['dropped_rows']}"
    )
    if val is not None:
        line += (
            f"; validation RMSE {report['rmse_validate_mm']:.4f} mm (mean offset removed "
            f"{report['rmse_validate_aligned_mm']:.4f} mm)"
        )
        for k, b in (report.get("baselines") or {}).items():
            line += f"; {k} baseline {b['rmse_validate_mm']:.4f} mm"
    if report["warnings"]:
        line += f"; warnings ({len(report['warnings'])}): " + " | ".join(report["warnings"])
    print(line)
    if not args.quiet:
        print(f"wrote {out / 'report.json'}, {out / 'report.md'} and {len(report['plots'])} plots")


def _calibration_size(args, data, val, n_segments: int):
    """``--subsample``, then the memory estimate: refused beyond what the machine has unless
    ``--no-resource-check`` (one line saying what to do). Returns the recordings calibrated and the
    estimate's line in a list."""
    from ._resources import MEMORY_SHARE, check_memory, cores, gb, machine_memory
    from .calibration._fits import MEMORY_BASE, MEMORY_PER_SAMPLE, peak_memory, worker_count

    if args.subsample is not None:
        if args.subsample < 1:
            raise CLIError(f"--subsample must be 1 or more, got {args.subsample}")
        keep = lambda d: d.subset(np.arange(d.n_samples) % args.subsample == 0)
        data, val = keep(data), None if val is None else keep(val)
    n = data.n_samples + (0 if val is None else val.n_samples)
    workers = worker_count(args.workers, n * n_segments)
    if args.workers is not None and workers < args.workers:
        print(
            f"tension-zones: note: --workers {args.workers} capped at {workers} (one per core beyond the "
            f"first, at least one; {cores()} core(s) here)",
            file=sys.stderr,
        )
    need = peak_memory(n * n_segments, workers)
    what = f"calibrating {n:,} samples x {n_segments} segment(s)" + (
        f" with {workers} worker process(es)" if workers else ""
    )
    if not args.no_resource_check:
        have = machine_memory() or 0
        fits = (MEMORY_SHARE * have / (1 + workers) - MEMORY_BASE) / (MEMORY_PER_SAMPLE * n_segments)
        k = math.ceil(n * (args.subsample or 1) / fits) if fits > 0 else 0
        check_memory(
            need,
            what,
            (f"pass --subsample {k} (one sample in {k}, in acquisition order)" if k else "pass fewer --workers")
            + " or --no-resource-check to run it anyway",
        )
    return data, val, [f"{what}: about {gb(need)} of memory (estimated)"]


def _out_dir(path: str, names=(), force: bool = False) -> Path:
    """A report folder, checked before any work: not a file, writable (or creatable: its nearest
    existing parent is a writable folder; nothing is created here), and holding none of ``names``
    unless ``force``."""
    import os

    out = Path(path)
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out must be a folder, {str(out)!r} is a file")
    old = [n for n in names if (out / n).exists()]
    if old and not force:
        raise CLIError(
            f"--out {str(out)!r} already holds a report ({old[0]}); pass --force to replace it or choose another folder"
        )
    parent = out
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise CLIError(f"--out {str(out)!r} cannot be created: {str(parent)!r} is a file")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise CLIError(f"--out {str(out)!r} is not writable ({str(parent)!r} is read-only)")
    return out


def cmd_examples(args) -> None:
    """List the example files that ship with the package, or copy them into a folder."""
    from ._examples import EXAMPLES, copy_examples, list_examples

    if args.copy is None:
        print(f"example files in {EXAMPLES} (copy them with --copy DIR):")
        for name in list_examples():
            print(f"  {name}")
        return
    paths = copy_examples(args.copy, force=args.force)
    if not args.quiet:
        print(f"copied {len(paths)} example files into {args.copy}")


def _add_examples_parser(sub) -> None:
    e = sub.add_parser("examples", help="list the example files that ship with the package, or copy them")
    e.add_argument("--copy", metavar="DIR", help="copy every example file into DIR (keeping sub-folders)")
    e.add_argument("--force", action="store_true", help="replace example files already in DIR")
    e.add_argument("--quiet", action="store_true", help="no summary line")
    e.set_defaults(func=cmd_examples)


def _add_calibrate_parser(sub) -> None:
    c = sub.add_parser("calibrate", help="fit a robot to tracker data, find and add missing effects")
    c.add_argument(
        "data", help="measurement CSV (tension_zones/MODEL.md Sec. 6, or the OpenCR format with --format opencr)"
    )
    c.add_argument("--design", required=True, help='design JSON: one segment, or {"segments": [...]} for several')
    c.add_argument("--out", required=True, help="output folder (report.json, report.md, plots)")
    c.add_argument(
        "--format",
        choices=("model", "opencr"),
        default="model",
        help="the data files' reader: model (tension_zones/MODEL.md Sec. 6, default) or opencr (the OpenCR lab's "
        "servo_<id>_mm recordings)",
    )
    c.add_argument("--validate", help="a second recording of the same robot, only predicted after the selection")
    c.add_argument(
        "--effects",
        help="candidate effects, comma-separated (default: the library but for the opt-in "
        "bending_friction); +NAME adds an opt-in effect to the default library, e.g. +bending_friction",
    )
    c.add_argument(
        "--holdout",
        type=float,
        default=None,
        help="fraction held out for the decisions (default 0.25: the tail of the acquisition "
        "order, or every 4th pattern group of a labelled recording)",
    )
    c.add_argument("--robust", action="store_true", help="Huber loss (tracker glitches)")
    c.add_argument(
        "--drop-bad", action="store_true", help="drop isolated bad rows (listed in the report) instead of failing"
    )
    _add_force(c, "an existing report in --out")
    _add_resource_check(c, "a memory estimate beyond the memory here")
    c.add_argument(
        "--subsample",
        type=int,
        metavar="K",
        help="keep every Kth sample of the recordings (in acquisition order), e.g. for one too large "
        "for the computer's memory",
    )
    c.add_argument(
        "--workers",
        type=int,
        default=None,
        help="processes running the loop's independent fits alongside this one (default: one per "
        "spare core, at most 4, for 1024 samples x segments or more; 0: none; a count asked for "
        "is capped at one per spare core); the report is the same with any",
    )
    c.add_argument("--quiet", action="store_true", help="only the one-line summary")
    c.set_defaults(func=cmd_calibrate)


# ---- explore: design-space exploration ----------------------------------------------
#: The seconds JAX's own ``initialization_timeout`` runs past ``--coordinator-timeout``: past it,
#: ``jax.distributed.initialize`` aborts the process from C++ (a stack trace, status 134), so the
#: command's own deadline (:func:`_deadline`) must come first.
JOIN_MARGIN_S = 10


def _init_distributed(args) -> None:
    """Join a ``jax.distributed`` run (before anything touches a JAX device). Every process, process
    0 as well as the others, gives up in one line (status 2) where the run has not come together
    within ``--coordinator-timeout`` seconds: a worker first waits for process 0 to answer
    (:func:`_wait_for_coordinator`), then every process waits for all of them to join."""
    import time

    given = {"--coordinator": args.coordinator, "--num-processes": args.num_processes, "--process-id": args.process_id}
    if not args.distributed and all(v is None for v in given.values()):
        return
    timeout = _positive("--coordinator-timeout", args.coordinator_timeout)
    deadline = time.monotonic() + timeout
    missing = [k for k, v in given.items() if v is None]
    if len(missing) < 3:  # explicit coordinates: all three
        if missing:
            raise CLIError(f"{', '.join(given)} go together: {missing[0]} is missing")
        kw = {
            "coordinator_address": args.coordinator,
            "num_processes": args.num_processes,
            "process_id": args.process_id,
        }
        if args.process_id != 0:
            _wait_for_coordinator(args.coordinator, timeout)
    else:  # --distributed: the cluster's environment says (SLURM, Open MPI, ...)
        kw = {}
    import jax

    left = max(1.0, deadline - time.monotonic())  # JAX counts whole seconds
    with _deadline(left, _not_joined(args, timeout)):
        try:
            jax.distributed.initialize(**kw, initialization_timeout=math.ceil(left) + JOIN_MARGIN_S)
        except (RuntimeError, ValueError) as e:
            raise CLIError(f"jax.distributed.initialize failed: {str(e).splitlines()[0]}") from None


def _not_joined(args, timeout: float) -> str:
    """The one line of a distributed run that did not come together within ``timeout`` seconds."""
    if args.coordinator is None:
        return (
            f"the processes of the distributed run did not all join within {timeout:g} s; check that the "
            "cluster started every one of them (e.g. srun's task count), or raise --coordinator-timeout"
        )
    n = args.num_processes
    return (
        f"not every one of the {n} processes (--num-processes) joined --coordinator {args.coordinator} within "
        f"{timeout:g} s (this is process {args.process_id}); start every --process-id 0..{n - 1} with the same "
        "--coordinator and --num-processes, or raise --coordinator-timeout"
    )


@contextlib.contextmanager
def _deadline(seconds: float, message: str):
    """End the process with ``message`` as its one error line (status 2) where the block has not
    ended within ``seconds``: for a call that cannot be interrupted from Python, such as
    ``jax.distributed.initialize``, which waits in C++ (and past its own timeout aborts the process)."""
    import threading

    def end():
        with contextlib.suppress(OSError):
            os.write(2, f"tension-zones: error: {message}\n".encode())
        os._exit(2)

    timer = threading.Timer(seconds, end)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()


def _wait_for_coordinator(address: str, timeout: float) -> None:
    """Connect to ``HOST:PORT`` until it answers or ``timeout`` seconds have passed, then raise a
    one-line CLIError: past its ``initialization_timeout``, ``jax.distributed.initialize`` aborts the
    process from C++ (a stack trace, status 134) instead of raising."""
    import socket
    import time

    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise CLIError(f"--coordinator must be HOST:PORT, got {address!r}")
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection((host.strip("[]"), int(port)), timeout=max(0.1, min(5.0, timeout))):
                return
        except OSError as e:
            reason = e.strerror or type(e).__name__
        if time.monotonic() >= deadline:
            raise CLIError(
                f"--coordinator {address} did not answer within {timeout:g} s ({reason}); start "
                "process 0 first, check the address, or raise --coordinator-timeout"
            )
        time.sleep(0.25)


def cmd_explore(args) -> None:
    import time

    import jax

    from .design._explore import check_front, default_front, explore, plan, summary
    from .design._space import load_space
    from .plots import write_front

    _init_distributed(args)
    space = load_space(args.space)
    front = default_front(space) if args.front is None else [c.strip() for c in args.front.split(",")]
    check_front(space, front)
    check = not args.no_resource_check
    line = plan(space, check)  # the work, said up front (beyond the memory here or the work's caps: refused)
    if not args.quiet and jax.process_index() == 0:
        print(line)
    t0 = time.perf_counter()
    table = explore(space, args.out, quiet=args.quiet, log=print, resource_check=check)
    if table is None:  # another process of a distributed run: process 0 writes
        return
    paths = write_front(table, args.out, front)
    print(summary(table, time.perf_counter() - t0, front))
    if not args.quiet:
        print(f"wrote {Path(args.out) / 'table.npz'}, table.csv, manifest.json and {', '.join(p.name for p in paths)}")


def _add_explore_parser(sub) -> None:
    e = sub.add_parser(
        "explore", help="explore a design space: per-design workspace statistics, Pareto front, plots (resumable)"
    )
    e.add_argument("--space", required=True, help="design-space JSON (keys: tension_zones/design/README.md)")
    e.add_argument(
        "--out", required=True, help="output folder: new or empty, or holding this same exploration (resumed)"
    )
    e.add_argument(
        "--front",
        help="two or three table columns for the Pareto front, comma-separated, "
        "each optionally min:/max: (default: pitch_radius_mm, "
        "dp_max_reduced_worst, and deflection_mm_reduced_worst with a load, "
        "else controllable_fraction)",
    )
    _add_resource_check(
        e, "a chunk's memory estimate beyond the memory here, too many chunks, too long an estimated computing time"
    )
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    d = e.add_argument_group("several processes and hosts (jax.distributed)")
    d.add_argument(
        "--distributed",
        action="store_true",
        help="join a jax.distributed run whose coordinates the cluster gives (e.g. under srun)",
    )
    d.add_argument("--coordinator", help="HOST:PORT of process 0 (with --num-processes, --process-id)")
    d.add_argument("--num-processes", type=int, help="number of processes")
    d.add_argument("--process-id", type=int, help="this process's index, 0 .. N-1")
    d.add_argument(
        "--coordinator-timeout",
        type=float,
        default=60.0,
        metavar="S",
        help="seconds to wait for the coordinator (process 0) to answer, and for every process "
        "to join, before giving up (default 60)",
    )
    e.set_defaults(func=cmd_explore)


# ---- end explore -------------------------------------------------------------------------------


def _add_force(parser, what: str) -> None:
    parser.add_argument("--force", action="store_true", help=f"overwrite {what}")


def _add_resource_check(parser, what: str) -> None:
    parser.add_argument(
        "--no-resource-check",
        action="store_true",
        help=f"run even what the resource checks refuse up front ({what})",
    )


class _Parser(argparse.ArgumentParser):
    """argparse with the command line's error rule: one line, exit status 2 (no usage block)."""

    def error(self, message):
        cmd = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        self.exit(2, f"tension-zones: error: {cmd}{_one_line(message)} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="tension-zones",
        description="Tension transition zones and reduced Jacobians for wire-actuated continuum robots.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    m = sub.add_parser("maps", help="draw a design's tension map and print its sector table")
    m.add_argument(
        "--design",
        help="a design file: one segment, or a robot (each segment's map, the others straight and bent)",
    )
    m.add_argument("--wires", type=int, help="number of wires (>= 3), without --design")
    m.add_argument("--angles", help="wire angles in degrees, comma-separated (default: even), without --design")
    m.add_argument(
        "--bend", type=float, help="a robot: the other segments' bending in the second row (deg, default 45)"
    )
    m.add_argument("--out", required=True, help="output PNG file")
    _add_force(m, "an existing --out file")
    m.add_argument("--quiet", action="store_true", help="print only the table")
    m.set_defaults(func=cmd_maps)

    o = sub.add_parser("optimize", help="search wire count, pitch radius, stiffness and placement")
    o.add_argument(
        "--scenario",
        required=True,
        help="scenario JSON (keys: tension_zones/design/README.md; examples: tension-zones examples)",
    )
    o.add_argument(
        "--design",
        help="start from this robot (a design file, e.g. a calibration's calibrated.design.json): each "
        "segment's values the scenario leaves out are the robot's, fixed; its calibrated play the joint "
        "uncertainty; result.json's 'start' is the robot itself under the scenario",
    )
    o.add_argument("--out", required=True, help="output folder (result.json, tradeoff.png, ...)")
    _add_force(o, "an earlier result in --out")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    o.set_defaults(func=cmd_optimize)

    r = sub.add_parser("reproduce", help="reproduce the paper's figures and tables into a folder")
    r.add_argument("--out", default="reproduce_out", help="output folder (default: reproduce_out)")
    _add_force(r, "the files of a non-empty --out folder")
    r.add_argument("--quiet", action="store_true", help="no progress output")
    r.set_defaults(func=cmd_reproduce)
    _add_sweep_parser(sub)
    _add_calibrate_parser(sub)
    _add_examples_parser(sub)
    _add_explore_parser(sub)
    return p


def _one_line(e: Exception) -> str:
    lines = (line.strip() for line in str(e).splitlines())
    return " ".join(line for line in lines if line) or type(e).__name__


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line on stderr, without the source line Python would print."""
    print(f"tension-zones: warning: {_one_line(message)}", file=sys.stderr)


#: After Ctrl-C, the seconds a command has to unwind (its ``finally`` blocks remove staged outputs)
#: before :func:`_interrupt_watchdog` ends the process: Python sees the KeyboardInterrupt only between
#: bytecodes, and a compiled JAX program or a NumPy call may not return for hours.
INTERRUPT_GRACE_S = 2.0


def _end_interrupted() -> None:
    """The end of a command that did not stop by itself after Ctrl-C: its worker processes killed, its
    hidden temporaries removed (the outputs being written: nothing is left that looks finished or that
    a rerun trips on), one line, exit status 130, without unwinding."""
    import multiprocessing

    from ._io import remove_temporaries

    for p in multiprocessing.active_children():
        p.kill()
    remove_temporaries()
    with contextlib.suppress(OSError):
        os.write(2, b"tension-zones: interrupted\n")
    os._exit(130)


@contextlib.contextmanager
def _interrupt_watchdog(grace: float = INTERRUPT_GRACE_S):
    """Ctrl-C stops the command within ``grace`` seconds even while the main thread is inside a
    compiled program: the C-level signal handler writes to a wake-up socket (``signal.set_wakeup_fd``),
    which a thread watches; if the command has not ended ``grace`` seconds later, the thread ends it
    (:func:`_end_interrupted`). Off where it cannot be set up (not the main thread)."""
    import signal
    import socket
    import threading

    try:
        r, w = socket.socketpair()
        w.setblocking(False)
        old = signal.set_wakeup_fd(w.fileno())
    except (ValueError, OSError):  # not the main thread of the main interpreter
        yield
        return
    done = threading.Event()

    def watch():
        with r:
            while (byte := r.recv(1)) and not done.is_set():
                if byte[0] == signal.SIGINT and not done.wait(grace):
                    _end_interrupted()

    def unraisable(u, hook=sys.unraisablehook):
        # Ctrl-C landing in a callback Python cannot raise from (JAX's garbage-collection hook) is
        # not printed as "Exception ignored": the thread above ends the command
        if not isinstance(u.exc_value, KeyboardInterrupt):
            hook(u)

    threading.Thread(target=watch, name="tension-zones-interrupt", daemon=True).start()
    old_hook, sys.unraisablehook = sys.unraisablehook, unraisable
    try:
        yield
    finally:
        sys.unraisablehook = old_hook
        done.set()
        signal.set_wakeup_fd(old)
        with contextlib.suppress(OSError):
            w.send(b"\0")  # wakes the thread, which sees ``done`` and ends
        w.close()


def _exit(code: int) -> NoReturn:
    """End the process with status ``code``. While a program compiles on a thread (a command
    interrupted or failed mid-calibration leaves it: ``Runner.close`` does not wait for it), without
    the interpreter's shutdown, which would wait for the compile (``engine_ahead``): Ctrl-C must end
    the command within seconds."""
    import threading

    if any(t.name == COMPILE_THREAD and t.is_alive() for t in threading.enumerate()):
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        os._exit(code)
    sys.exit(code)


def run(argv=None) -> NoReturn:
    """The ``tension-zones`` command: :func:`main` (which returns the exit status, for callers in
    this process), then the process ends (:func:`_exit`)."""
    _exit(main(argv))


def main(argv=None) -> int:
    import warnings

    parser = build_parser()
    args = parser.parse_args(argv)  # --help and usage errors (one line, status 2) exit here
    try:
        with warnings.catch_warnings(), _interrupt_watchdog():
            warnings.showwarning = _show_warning
            args.func(args)
    except (CLIError, ValueError, OSError) as e:  # OSError: missing, unreadable, unwritable files
        print(f"tension-zones: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("tension-zones: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the output was piped into a program that stopped reading (e.g. head)
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    return 0


if __name__ == "__main__":
    run()
