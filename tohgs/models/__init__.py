"""Components, the trainable networks (:mod:`tohgs.models.component`): the diffusers, PointNet++, the one
training loop and the one checkpoint format. Importing this package imports no torch: the workflow and the
config validation use :func:`component_kind_exists` and :data:`CHECKED_KINDS` at parse time."""

from __future__ import annotations

from pathlib import Path

from tohgs.kinds import kind_modules

CHECKED_KINDS = ("contact_diffuser", "grasp_diffuser", "contact_gen")  # component kinds with checks (checks.py)
_MODELS_DIR = Path(__file__).resolve().parent


def component_kinds() -> list[str]:
    """Every component kind: a module ``tohgs/models/<kind>.py`` that binds ``COMPONENT`` (read as text)."""
    return list(kind_modules(_MODELS_DIR, "COMPONENT"))


def component_kind_exists(kind: str) -> bool:
    """Whether ``kind`` is a component kind (:func:`component_kinds`; ``train``, the loop's module, is not)."""
    return kind in component_kinds()
