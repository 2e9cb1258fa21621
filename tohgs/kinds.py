"""Kinds found by name, a leaf module: the component kinds (modules of :mod:`tohgs.models` with a
``COMPONENT``) and the method kinds (modules of :mod:`tohgs.methods` with a ``METHOD``), read as text so
that the workflow's parse imports no torch."""

from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

#: What a kind's name looks like (a module name).
KIND = re.compile(r"[a-z][a-z0-9_]*")


@lru_cache(maxsize=None)
def kind_modules(folder: Path, marker: str) -> tuple[str, ...]:
    """The modules of ``folder`` (their names, sorted) that bind ``marker`` at the top level
    (``COMPONENT = ContactDiffuser``): the kinds; a helper module beside them (``train.py``) is none."""
    binds = re.compile(rf"^{re.escape(marker)}\s*=", re.MULTILINE)
    return tuple(sorted(p.stem for p in folder.glob("*.py") if KIND.fullmatch(p.stem) and binds.search(p.read_text())))
