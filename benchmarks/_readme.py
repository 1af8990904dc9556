"""Write a benchmark's results into ``benchmarks/README.md`` between its ``<!-- NAME START/END -->`` markers
(one place for every benchmark script; a missing section is appended under ``title``)."""

from pathlib import Path

README = Path(__file__).resolve().parent / "README.md"


def write_section(name: str, md: str, title: str | None = None) -> None:
    text = README.read_text()
    a, b = f"<!-- {name} START -->", f"<!-- {name} END -->"
    if a not in text:
        text += f"\n## {title or name}\n\n{a}\n{b}\n"
    head, rest = text.split(a, 1)
    _, tail = rest.split(b, 1)
    README.write_text(f"{head}{a}\n{md}\n{b}{tail}")
