"""Same-named modules of the package say so: each names its twins in a ``Twins:`` paragraph.

Issue "One engine": no two modules with the same file name in different folders unless they
are the same concept at two layers, which their docstrings say. Every module whose file name
(other than ``__init__.py``) occurs more than once under ``multiarm_pin/`` must have in its
module docstring a paragraph that begins ``Twins: `` and names every other module of that file
name by its dotted path in double backticks; a module whose file name is unique must have no such
paragraph (a stale one after a rename). Docstrings are read with :func:`ast.get_docstring`,
nothing is imported. The checker is tested on a planted package first
(:func:`test_the_checker_finds_missing_and_stale_twins`), so that a clean result means something.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "multiarm_pin"

TWINS_PREFIX = "Twins: "
"""How the paragraph that names a module's twins begins."""


def same_named(package: Path) -> dict[str, list[Path]]:
    """File name -> its files under ``package``, for every name (not ``__init__.py``) that
    occurs more than once."""
    groups = defaultdict(list)
    for f in sorted(package.rglob("*.py")):
        if f.name != "__init__.py":
            groups[f.name].append(f)
    return {name: files for name, files in groups.items() if len(files) > 1}


def dotted(package: Path, f: Path) -> str:
    """The dotted module name of file ``f`` of ``package`` (a folder named like the package)."""
    return ".".join(f.relative_to(package.parent).with_suffix("").parts)


def twins_paragraph(f: Path) -> str | None:
    """The docstring paragraph of module ``f`` that begins with :data:`TWINS_PREFIX`, joined
    into one line, or None."""
    doc = ast.get_docstring(ast.parse(f.read_text(encoding="utf-8"), str(f))) or ""
    for paragraph in re.split(r"\n\s*\n", doc):
        if paragraph.startswith(TWINS_PREFIX):
            return " ".join(paragraph.split())
    return None


def twin_problems(package: Path) -> list[str]:
    """One line per module of ``package`` whose ``Twins:`` paragraph is missing, misses a twin
    (each named by its dotted path in double backticks), or stands in a module whose file name
    is unique."""
    problems = []
    groups = same_named(package)
    for files in groups.values():
        for f in files:
            paragraph = twins_paragraph(f)
            if paragraph is None:
                problems.append(f"{f}: no paragraph beginning {TWINS_PREFIX!r} in its docstring")
                continue
            named = set(re.findall(r"``([\w.]+)``", paragraph))
            for other in files:
                if other != f and dotted(package, other) not in named:
                    problems.append(f"{f}: its {TWINS_PREFIX!r} paragraph does not name "
                                    f"``{dotted(package, other)}``")
    for f in sorted(package.rglob("*.py")):
        if f.name != "__init__.py" and f.name not in groups and twins_paragraph(f) is not None:
            problems.append(f"{f}: a {TWINS_PREFIX!r} paragraph, but no other module is "
                            f"named {f.name}")
    return problems


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")


def test_the_checker_finds_missing_and_stale_twins(tmp_path):
    pkg = tmp_path / "planted"
    _write(pkg / "__init__.py", "")
    _write(pkg / "a" / "__init__.py", "")
    _write(pkg / "b" / "__init__.py", "")
    _write(pkg / "c" / "__init__.py", "")
    _write(pkg / "a" / "loop.py", '"""A loop.\n\nTwins: ``planted.b.loop`` (its kernel)."""\n')
    _write(pkg / "b" / "loop.py", '"""A kernel.\n\nTwins: ``planted.a.loop`` (its driver)."""\n')
    _write(pkg / "c" / "single.py", '"""Alone."""\n')
    assert twin_problems(pkg) == []

    _write(pkg / "c" / "loop.py", '"""A third loop, undocumented."""\n')
    problems = twin_problems(pkg)
    assert len(problems) == 3, problems
    assert any("c/loop.py: no paragraph" in p for p in problems)
    assert sum("does not name ``planted.c.loop``" in p for p in problems) == 2

    (pkg / "c" / "loop.py").unlink()
    _write(pkg / "c" / "single.py", '"""Alone.\n\nTwins: ``planted.a.single``."""\n')
    assert twin_problems(pkg) == [f"{pkg / 'c' / 'single.py'}: a 'Twins: ' paragraph, "
                                  "but no other module is named single.py"]


def test_same_named_modules_name_their_twins():
    assert same_named(PACKAGE), "the package has no repeated file names: is PACKAGE right?"
    problems = twin_problems(PACKAGE)
    assert not problems, "\n".join(problems)
