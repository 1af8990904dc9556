"""House rules of the package: what importing it does, what its text may say, what it names."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(code, env):
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip().splitlines()


def test_import_enables_float64_and_nothing_else(tmp_path):
    """``import tension_zones`` leaves ``XLA_FLAGS`` and the file system alone; a sub-package that
    loads JAX applies the XLA settings, and JAX makes the cache folder at its first compile."""
    home = tmp_path / "home"
    home.mkdir()
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("TENSION_ZONES_CACHE", "JAX_COMPILATION_CACHE_DIR", "XDG_CACHE_HOME", "JAX_ENABLE_X64")
    }
    env.update(
        HOME=str(home),
        XLA_FLAGS="--xla_force_host_platform_device_count=1",
        PYTHONPATH=os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]),
    )
    code = """
import os
import tension_zones
print(os.environ["XLA_FLAGS"])
print(os.environ.get("JAX_ENABLE_X64"))
print(sorted(os.listdir(os.path.expanduser("~"))))
import jax
print(jax.config.jax_enable_x64, jax.config.jax_compilation_cache_dir)
"""
    flags, x64, listing, config = _run(code, env)
    assert flags == "--xla_force_host_platform_device_count=1"
    assert x64 == "1" and listing == "[]" and config == "True None"
    assert list(home.iterdir()) == []

    code = """
import os
import jax, jax.numpy as jnp
import tension_zones
import tension_zones.model
print(os.environ["XLA_FLAGS"])
print(jax.config.jax_compilation_cache_dir)
print(os.path.isdir(jax.config.jax_compilation_cache_dir))
jax.jit(lambda x: jnp.sin(x) * 2.0)(jnp.arange(3.0)).block_until_ready()
print(os.path.isdir(jax.config.jax_compilation_cache_dir))
"""
    flags, folder, before, after = _run(code, env)
    assert flags.split() == [
        "--xla_force_host_platform_device_count=1",
        "--xla_cpu_enable_concurrency_optimized_scheduler=false",
    ]
    assert folder == str(home / ".cache" / "tension-zones" / "jax")
    assert (before, after) == ("False", "True")


#: What package text (code, comments, docstrings, CLI help, the READMEs beside the code) must not say: a measurement of a day
#: (a duration, a date, the machine it ran on) or a before/now comparison. Those live in git history
#: and in generated benchmark output; the code says what it does and why.
_NOTEBOOK = {
    "a duration": r"\b\d+(?:\.\d+)?(?: ?[-/] ?\d+(?:\.\d+)?)? ?(?:s|ms|us|min|mins|minutes?|seconds?|hours?)\b(?![(\[_]|\.\w)",
    "a date": r"\b20\d\d-[01]\d(?:-[0-3]\d)?\b",
    "a machine": r"(?i)\bthis (?:\d+-core |shared )?machine\b|\b\d+-core\b|\blaptop\b|% CPU\b",
    "a before/now figure": (
        r"(?i)\b(?:works|runs|is|as) as before\b|\bas before\b|\bwas [\d.]+.{0,40}\bnow\b"
        r"|\d(?: ?(?:s|mm|%|x))? ?-> ?\d|\d(?: ?(?:s|mm|us|%))? against \d|instead of \d+(?:[.,-]\d+)*\b"
    ),
}


def _package_lines():
    pkg = ROOT / "tension_zones"
    for path in sorted(pkg.rglob("*.py")) + sorted(pkg.rglob("*.md")):
        for i, line in enumerate(path.read_text().splitlines(), 1):
            yield path.relative_to(ROOT), i, line


def _notebook_lines(lines):
    import re

    found = []
    for path, i, line in lines:
        for what, pattern in _NOTEBOOK.items():
            if re.search(pattern, line):
                found.append(f"{path}:{i}: {what}: {line.strip()}")
    return found


def test_package_code_cites_no_timing_date_machine_or_before_and_now():
    assert _notebook_lines(_package_lines()) == []


def test_the_notebook_patterns_catch_what_they_are_for_and_not_units():
    bad = [
        "took 382 s against 86 s",
        "12.24-12.50 s -> 10.82 s wall",
        "(5 s with the flag off)",
        "a compile takes 10-15 s",
        "8.7 / 8.8 s",
        "0.3-0.5 s in every process",
        "about 4 min",
        "timings, 2026-12-04",
        "on this 2-core machine",
        "Measured on this machine",
        "works as before",
        "validation 5.78 -> 4.29 mm",
        "4-5 iterations instead of 8-9",
        "(one run each: 153 against 136 us)",
    ]
    good = [
        "``B`` (2S,) the bending vectors",
        "tau >= f_min s.t. A tau = rhs",
        "(N mm) for x (2S,)",
        "a 0.4 N lateral tip force",
        "stiffness 60 N/mm at 4.5 mm",
        "q (N,) (negative = pulled in)",
        "jaxlib 0.5.3 on",
        "(mm, N, rad; reported in deg)",
        "exp(d_k (mu_0 + mu_1 w_ki))",
        "np.min(x)",
        "1 s_k of wire k",
        "||tau||^2 s.t. A tau",
        "one root instead of 2n",
        "before the selection is over",
    ]
    flagged = _notebook_lines((Path("x.py"), i, line) for i, line in enumerate(bad + good))
    assert sorted({int(f.split(":")[1]) for f in flagged}) == list(range(len(bad))), flagged


def test_docstrings_do_not_open_with_an_issue_number():
    import ast
    import re

    found = []
    for path in sorted((ROOT / "tension_zones").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                doc = ast.get_docstring(node)
                if doc and re.match(r"(?i)issue \d+", doc):
                    found.append(f"{path.relative_to(ROOT)}: {getattr(node, 'name', '<module>')}")
    assert found == []


def _docstrings(folder):
    import ast

    for path in sorted(folder.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            kinds = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)
            if isinstance(node, kinds) and (doc := ast.get_docstring(node)):
                yield path.relative_to(ROOT), node, doc


def test_test_docstrings_say_what_is_tested_not_its_history():
    import re

    lines = [
        (f"{path}:{getattr(node, 'name', '<module>')}", i, line)
        for path, node, doc in _docstrings(ROOT / "tests")
        for i, line in enumerate(doc.splitlines())
    ]
    found = [f for f in _notebook_lines(lines) if ": a before/now figure:" not in f or "->" in f]
    found += [
        f"{where}: {line}" for where, i, line in lines if i == 0 and re.match(r"(?i)(regression|issue \d+)\b", line)
    ]
    assert found == []


#: Text that names modules and files: the package's code (docstrings, comments, CLI help) and its
#: pages (the READMEs, the model specification, the documentation site's own pages).
def _named_in():
    pkg = ROOT / "tension_zones"
    pages = [p for p in sorted((ROOT / "docs" / "pages").rglob("*.md")) if not p.is_symlink()]
    return sorted(pkg.rglob("*.py")) + sorted(pkg.rglob("*.md")) + [ROOT / "README.md"] + pages


def test_every_module_named_in_code_and_pages_exists():
    import importlib
    import re

    found = set()
    for path in _named_in():
        for name in re.findall(r"\btension_zones(?:\.[A-Za-z_]\w*)+", path.read_text()):
            parts = name.split(".")
            for k in range(len(parts), 0, -1):  # the longest module, then attributes
                try:
                    obj = importlib.import_module(".".join(parts[:k]))
                except ImportError:
                    continue
                for attr in parts[k:]:
                    obj = getattr(obj, attr, None)
                if obj is None:
                    found.add(f"{path.relative_to(ROOT)}: {name}")
                break
    assert sorted(found) == []


#: Paths named as outputs or placeholders (``--out DIR``), not files of the repository.
_NOT_FILES = {"report.md"}
_PLACEHOLDERS = ("DIR/", "OUT/")


def test_every_file_named_in_code_and_pages_exists():
    """A path with a folder is looked for from the repository, the package, the naming file's folder
    and the shipped examples (``example_path``; ``ex/`` is the README's copy of them); a bare
    ``.py``/``.md``/``.ipynb`` name anywhere in the repository."""
    import re

    pattern = re.compile(r"(?<![\w./~$-])((?:[\w-]+/)*[\w.-]*\w\.(?:py|md|json|csv|ipynb|toml|yml|yaml|txt))\b")
    names = {p.name for p in ROOT.rglob("*") if ".git" not in p.parts}
    examples = ROOT / "tension_zones" / "examples"
    found = set()
    for path in _named_in():
        for token in pattern.findall(path.read_text()):
            if token in _NOT_FILES or token.startswith(_PLACEHOLDERS):
                continue
            if "/" not in token:
                ok = not token.endswith((".py", ".md", ".ipynb")) or token in names
            else:
                local = token.removeprefix("ex/")
                ok = any(
                    p.exists()
                    for p in (ROOT / token, ROOT / "tension_zones" / token, path.parent / token, examples / local)
                )
            if not ok:
                found.add(f"{path.relative_to(ROOT)}: {token}")
    assert sorted(found) == []


def _imports(path: Path, module: str) -> set[str]:
    """The package modules ``module`` (file ``path``) imports, at any depth of its code (a function's
    lazy import too): ``tension_zones.a.b`` names, a name imported from a package counted as its module
    where one exists."""
    import ast

    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("tension_zones")}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
            elif (node.module or "").startswith("tension_zones"):
                base = node.module
            else:
                continue
            subs = {f"{base}.{a.name}" for a in node.names}
            out |= {s for s in subs if _module_file(s) is not None} or {base}
    return out - {module}


def _module_file(name: str) -> Path | None:
    p = ROOT.joinpath(*name.split("."))
    return next((f for f in (p.with_suffix(".py"), p / "__init__.py") if f.is_file()), None)


def test_no_import_cycle_between_modules():
    """Data flow one way (model -> analysis -> design, calibration -> report, plots, CLI): no module
    imports, even lazily inside a function, one that imports it back (a package's ``__init__`` aside,
    which re-exports its own modules)."""
    files = {
        ".".join(f.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): f
        for f in (ROOT / "tension_zones").rglob("*.py")
    }
    graph = {m: {t for t in _imports(f, m) if t in files and not m.startswith(t + ".")} for m, f in files.items()}
    cycles, state = [], {}

    def visit(m, stack):
        state[m] = 1
        for t in graph[m]:
            if state.get(t) == 1:
                cycles.append(stack[stack.index(t) :] + [t])
            elif t not in state:
                visit(t, stack + [t])
        state[m] = 2

    for m in graph:
        if m not in state:
            visit(m, [m])
    assert cycles == []


def test_readmes_are_short_front_doors():
    """The README at most 8 KB, each README beside the code at most 10 KB, the benchmarks' at most 15 KB
    (a KB as 1000 bytes, the stricter reading)."""
    limits = {ROOT / "README.md": 8000, ROOT / "benchmarks" / "README.md": 15_000}
    limits.update({p: 10_000 for p in (ROOT / "tension_zones").rglob("README.md")})
    over = [f"{p.relative_to(ROOT)}: {p.stat().st_size} bytes" for p, n in limits.items() if p.stat().st_size > n]
    assert over == []


#: The most lines a function of the package may span, its docstring and nested functions included.
MAX_FUNCTION_LINES = 100


def _function_lengths(folder: Path) -> list[tuple[int, str]]:
    """``(lines, "file:line name")`` of every function and method under ``folder``, nested ones too."""
    import ast

    out = []
    for path in sorted(folder.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                out.append(
                    (node.end_lineno - node.lineno + 1, f"{path.relative_to(folder.parent)}:{node.lineno} {node.name}")
                )
    return out


def test_no_function_over_a_hundred_lines(tmp_path):
    """Every function in the package spans at most ``MAX_FUNCTION_LINES`` lines; the count finds a
    long one, nested in another, where there is one."""
    long = sorted(f for f in _function_lengths(ROOT / "tension_zones") if f[0] > MAX_FUNCTION_LINES)
    assert long == []
    body = "".join(f"        x = {k}\n" for k in range(MAX_FUNCTION_LINES))
    (tmp_path / "m.py").write_text(f"def outer():\n    def inner():\n{body}")
    assert sorted(_function_lengths(tmp_path))[-2:] == [
        (MAX_FUNCTION_LINES + 1, f"{tmp_path.name}/m.py:2 inner"),
        (MAX_FUNCTION_LINES + 2, f"{tmp_path.name}/m.py:1 outer"),
    ]
