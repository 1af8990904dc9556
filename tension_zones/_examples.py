"""The example files that ship with the package (``tension_zones/examples/``, see its README)."""

from __future__ import annotations

import shutil
from pathlib import Path

EXAMPLES = Path(__file__).parent / "examples"


def list_examples() -> list[str]:
    """The example files, as names relative to the examples folder (``synthetic/unknown_a_3w.csv``)."""
    return sorted(
        str(p.relative_to(EXAMPLES))
        for p in EXAMPLES.rglob("*")
        if p.is_file() and p.name != "README.md" and "__pycache__" not in p.parts
    )


def example_path(name: str) -> Path:
    """The path of one example file (``"ftdcr_v4/train.csv"``); a ``ValueError`` names the known ones."""
    p = EXAMPLES / name
    if not p.is_file() or name not in list_examples():
        raise ValueError(f"no example {name!r}; known: {', '.join(list_examples())}")
    return p


def copy_examples(dest, force: bool = False) -> list[Path]:
    """Copy every example file into ``dest`` (keeping the sub-folders); existing files are not
    replaced unless ``force``. Returns the written paths."""
    dest = Path(dest)
    if dest.exists() and not dest.is_dir():
        raise ValueError(f"{str(dest)!r} is a file, not a folder")
    names = list_examples()
    clash = [n for n in names if (dest / n).exists()]
    if clash and not force:
        raise ValueError(
            f"{str(dest / clash[0])!r} already exists; pass force=True (--force) to replace the example files there"
        )
    out = []
    for n in names:
        target = dest / n
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(EXAMPLES / n, target)
        out.append(target)
    shutil.copyfile(EXAMPLES / "README.md", dest / "README.md") if force or not (dest / "README.md").exists() else None
    return out
