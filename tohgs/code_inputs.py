"""The code inputs of a workflow rule, derived from the imports of its script (read statically, so the
workflow's parse never imports the library's heavy modules).

A job's code is every ``tohgs`` source file its script imports, directly or through other ``tohgs``
modules, anywhere in a file (a lazy import inside a function counts, a package's ``__init__.py`` runs with
its modules so it counts too), plus the modules it loads by name (a component or method kind). Listing
them as inputs makes an edit of any of them make the job stale, and nothing is kept by hand.
"""

from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path


@lru_cache(maxsize=None)
def direct_imports(path: Path, root: Path) -> frozenset[Path]:
    """The ``tohgs`` source files (under ``root``, the checkout) that ``path`` names in an import."""
    tree = ast.parse(Path(path).read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
    files: set[Path] = set()
    for name in names:
        parts = name.split(".")
        if parts[0] != "tohgs":
            continue
        for k in range(1, len(parts) + 1):
            base = root.joinpath(*parts[:k])
            files |= {f for f in (base.with_suffix(".py"), base / "__init__.py") if f.is_file()}
    return frozenset(files)


def import_closure(path: str | Path, root: str | Path) -> set[Path]:
    """Every ``tohgs`` source file ``path`` reaches through imports (not ``path`` itself unless it is reached)."""
    root = Path(root).resolve()
    seen: set[Path] = set()
    todo = [Path(path).resolve()]
    while todo:
        for dep in direct_imports(todo.pop(), root):
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return seen


def code_inputs(script: str | Path, modules: tuple[str, ...], root: str | Path) -> list[Path]:
    """The sorted code inputs of a rule whose script is ``script`` and that loads ``modules`` by name
    (``"models/grasp_diffuser"``: ``tohgs/models/grasp_diffuser.py``).

    Raises:
        FileNotFoundError: a named module does not exist.
    """
    root = Path(root).resolve()
    files = import_closure(script, root)
    for name in modules:
        source = root / "tohgs" / f"{name}.py"
        if not source.is_file():
            raise FileNotFoundError(f"code input {name!r}: no module {source}")
        files |= {source} | import_closure(source, root)
    return sorted(files)
