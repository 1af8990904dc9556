"""The ``tension-zones`` command line: a thin shell around the library.

Errors are one line on stderr (``tension-zones: error: ...``) and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


class CLIError(Exception):
    """A user-facing error: printed as one line."""


def _parse_angles(text: str | None, n_wires: int | None):
    if text is None:
        return None
    try:
        vals = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise CLIError(f"--angles must be comma-separated numbers in degrees, got {text!r}") from None
    if n_wires is not None and len(vals) != n_wires:
        raise CLIError(f"--angles has {len(vals)} values but --wires is {n_wires}")
    return np.radians(vals)


def _design(args, length=20.0, pitch_radius=2.0):
    from .design import Design

    d = {"n_wires": args.wires, "length_mm": length, "pitch_radius_mm": pitch_radius}
    if getattr(args, "angles", None) is not None:
        d["wire_angles_deg"] = np.degrees(_parse_angles(args.angles, args.wires)).tolist()
    try:
        return Design.from_dict(d)
    except ValueError as e:
        raise CLIError(str(e)) from None


def _out_path(path: str, suffix: str) -> Path:
    p = Path(path)
    if p.suffix.lower() != suffix:
        raise CLIError(f"--out must end in {suffix}, got {path!r}")
    if not p.parent.exists():
        raise CLIError(f"the folder of --out does not exist: {str(p.parent)!r}")
    return p


def cmd_maps(args) -> None:
    import matplotlib.pyplot as plt

    from .plots import plot_tension_map
    from .zones import tension_map

    out = _out_path(args.out, ".png")
    design = _design(args)
    tmap = tension_map(design)
    fig, ax = plt.subplots(figsize=(6.4, 6.8))
    plot_tension_map(tmap, ax=ax)
    fig.savefig(out, dpi=130, bbox_inches="tight")
    plt.close(fig)
    print(tmap.table())
    if not args.quiet:
        print(f"wrote {out}")


def cmd_reproduce(args) -> None:
    from .reproduce import reproduce

    reproduce(Path(args.out), quiet=args.quiet)


# ---- calibrate (issue 6) ----------------------------------------------------------------------
def cmd_calibrate(args) -> None:
    from .calib import DataError, calibrate, load_csv, write_report
    from .design import Design

    try:
        design = Design.from_json(args.design)
        data = load_csv(args.data, n_wires=design.n_wires, length=float(design.length),
                        drop_bad=args.drop_bad)
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise CLIError(f"--out must be a folder, {str(out)!r} is a file")
        log = None if args.quiet else (lambda s: print(s, file=sys.stderr))
        res = calibrate(data, design, holdout=args.holdout, robust=args.robust, log=log)
    except DataError as e:
        raise CLIError(str(e)) from None
    report = write_report(res, out)
    found = ", ".join(e["name"] for e in report["effects"]) or "none"
    print(f"held-out RMSE: declared {report['rmse_declared_mm']:.4f} mm, nominal fit "
          f"{report['rmse_before_mm']:.4f} mm, after {report['rmse_after_mm']:.4f} mm "
          f"(noise floor {report['noise_floor_mm']:.4f} mm); effects added: {found}; "
          f"unexplained structure: {'yes' if report['unexplained_structure'] else 'no'}; "
          f"dropped rows: {report['dropped_rows']}")
    if not args.quiet:
        print(f"wrote {out / 'report.json'}, {out / 'report.md'} and {len(report['plots'])} plots")


def _add_calibrate_parser(sub) -> None:
    c = sub.add_parser("calibrate", help="fit a design to tracker data, find and add missing effects")
    c.add_argument("data", help="measurement CSV (MODEL.md Sec. 6)")
    c.add_argument("--design", required=True, help="declared design JSON")
    c.add_argument("--out", required=True, help="output folder (report.json, report.md, plots)")
    c.add_argument("--holdout", type=float, default=0.25,
                   help="fraction held out at the end of the acquisition order (default 0.25)")
    c.add_argument("--robust", action="store_true", help="Huber loss (tracker glitches)")
    c.add_argument("--drop-bad", action="store_true",
                   help="drop isolated bad rows (counted in the report) instead of failing")
    c.add_argument("--quiet", action="store_true", help="only the one-line summary")
    c.set_defaults(func=cmd_calibrate)
# ---- end calibrate ----------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="tension-zones",
        description="Tension transition zones and reduced Jacobians for wire-actuated continuum robots.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    m = sub.add_parser("maps", help="draw a design's tension map and print its sector table")
    m.add_argument("--wires", type=int, required=True, help="number of wires (>= 3)")
    m.add_argument("--angles", help="wire angles in degrees, comma-separated (default: even)")
    m.add_argument("--out", required=True, help="output PNG file")
    m.add_argument("--quiet", action="store_true", help="print only the table")
    m.set_defaults(func=cmd_maps)

    r = sub.add_parser("reproduce", help="reproduce the paper's figures and tables into a folder")
    r.add_argument("--out", default="reproduce_out", help="output folder (default: reproduce_out)")
    r.add_argument("--quiet", action="store_true", help="no progress output")
    r.set_defaults(func=cmd_reproduce)
    _add_calibrate_parser(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        args.func(args)
    except CLIError as e:
        print(f"tension-zones: error: {e}", file=sys.stderr)
        return 2
    except (ValueError, FileNotFoundError, PermissionError, IsADirectoryError) as e:
        print(f"tension-zones: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("tension-zones: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
