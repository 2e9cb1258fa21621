"""Kinds found by name, and what they declare, a leaf module: the component kinds (modules of
:mod:`tohgs.models` with a ``COMPONENT``) and the method kinds (modules of :mod:`tohgs.methods` with a
``METHOD``), read as text so that the workflow's parse imports no torch, and their declarations, the
schema's ``$defs`` blocks (``$defs.method_kinds.<kind>``, ``$defs.networks.<kind>``) and the built-in
methods (the ``methods`` default)."""

from __future__ import annotations

import copy
import re
from functools import lru_cache
from pathlib import Path
from typing import Any

import yaml

#: What a kind's name looks like (a module name).
KIND = re.compile(r"[a-z][a-z0-9_]*")
#: The workflow configuration's schema, the one place a kind is declared.
SCHEMA_PATH = Path(__file__).resolve().parent.parent / "workflow" / "schemas" / "config.schema.yaml"


@lru_cache(maxsize=None)
def kind_modules(folder: Path, marker: str) -> tuple[str, ...]:
    """The modules of ``folder`` (their names, sorted) that bind ``marker`` at the top level
    (``COMPONENT = ContactDiffuser``): the kinds; a helper module beside them (``train.py``) is none."""
    binds = re.compile(rf"^{re.escape(marker)}\s*=", re.MULTILINE)
    return tuple(sorted(p.stem for p in folder.glob("*.py") if KIND.fullmatch(p.stem) and binds.search(p.read_text())))


@lru_cache(maxsize=None)
def _schema(path: Path) -> dict[str, Any]:
    with open(path) as fh:
        return yaml.safe_load(fh)


def read_schema(path: Path | str = SCHEMA_PATH) -> dict[str, Any]:
    """A copy of the schema file as written (parsed once per process; :func:`tohgs.config.load_schema` adds
    what the registered kinds declare)."""
    return copy.deepcopy(_schema(Path(path)))


def schema_defs(name: str, path: Path = SCHEMA_PATH) -> dict[str, Any]:
    """A copy of the schema file's ``$defs.<name>`` (``method_kinds``, ``networks``): every kind's block."""
    return copy.deepcopy(_schema(Path(path)).get("$defs", {}).get(name, {}))


def schema_default(key: str, path: Path = SCHEMA_PATH) -> Any:
    """A copy of the schema file's default of the top-level config key ``key`` as written there (``methods``:
    the built-in methods; no overlay, no validation: :func:`tohgs.config.validate_config` fills the rest)."""
    return copy.deepcopy(_schema(Path(path))["properties"][key]["default"])
