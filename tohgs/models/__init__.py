"""Components, the trainable networks (:mod:`tohgs.models.component`): the diffusers, PointNet++, the one
training loop and the one checkpoint format. Importing this package imports no torch: the workflow and the
config validation use :func:`component_kind_exists` and :data:`CHECKED_KINDS` at parse time."""

from __future__ import annotations

import re
from pathlib import Path

CHECKED_KINDS = ("contact_diffuser", "grasp_diffuser", "contact_gen")  # component kinds with checks (checks.py)
_MODELS_DIR = Path(__file__).resolve().parent
_KIND = re.compile(r"[a-z][a-z0-9_]*")


def component_kind_exists(kind: str) -> bool:
    """Whether ``kind`` names a component module ``tohgs/models/<kind>.py`` (checked without importing it)."""
    return bool(_KIND.fullmatch(kind)) and (_MODELS_DIR / f"{kind}.py").is_file()


def component_kinds() -> list[str]:
    """Every component kind (a module of this package with a ``COMPONENT``)."""
    return sorted(p.stem for p in _MODELS_DIR.glob("*.py") if "COMPONENT =" in p.read_text())
