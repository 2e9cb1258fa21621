"""Components, the trainable networks (:mod:`tohgs.models.component`): the diffusers, PointNet++, the one
training loop and the one checkpoint format. Importing this package imports no torch: the workflow and the
config validation use :func:`component_kind_exists` and :func:`component_checks` at parse time."""

from __future__ import annotations

from pathlib import Path

from tohgs.kinds import kind_modules, schema_defs

_MODELS_DIR = Path(__file__).resolve().parent


def component_kinds() -> list[str]:
    """Every component kind: a module ``tohgs/models/<kind>.py`` that binds ``COMPONENT`` (read as text)."""
    return list(kind_modules(_MODELS_DIR, "COMPONENT"))


def component_kind_exists(kind: str) -> bool:
    """Whether ``kind`` is a component kind (:func:`component_kinds`; ``train``, the loop's module, is not)."""
    return kind in component_kinds()


def component_checks() -> dict[str, list[str]]:
    """The checks (names of :data:`tohgs.models.checks.CHECKS`) of each component kind that declares some:
    its schema block's ``x-checks`` (``$defs.networks.<kind>``), by kind."""
    return {k: list(v["x-checks"]) for k, v in schema_defs("networks").items() if v.get("x-checks")}
