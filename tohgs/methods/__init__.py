"""Methods: how a method's components compose into grasps for the test configurations.

A method is a config block under ``methods`` (:file:`config/README.md`): a ``label`` (its row name in the
tables), a ``kind`` and the kind's keys, which name components (``components.<name>``) or fixed sources
(``ground_truth``). Kind ``k`` is the class ``METHOD`` of ``tohgs.methods.<k>``
(:class:`tohgs.methods.base.Method`); one rule predicts any method (:func:`tohgs.methods.predict.predict`)
into ``results/predictions/<task>/<method>.zarr``.

This module is read at workflow parse time, so it imports neither torch nor the method modules.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

_METHODS_DIR = Path(__file__).resolve().parent
_KIND = re.compile(r"[a-z][a-z0-9_]*")
NOT_COMPONENT_KEYS = ("label", "kind", "settings")  # method keys that never name a component


def method_kind_exists(kind: str) -> bool:
    """Whether ``kind`` names a method module (without importing it)."""
    return bool(_KIND.fullmatch(kind)) and kind not in ("base", "predict") and (_METHODS_DIR / f"{kind}.py").is_file()


def method_kinds() -> list[str]:
    """Every method kind (a module of this package with a ``METHOD``)."""
    return sorted(p.stem for p in _METHODS_DIR.glob("*.py") if method_kind_exists(p.stem) and "METHOD =" in p.read_text())


def method_components(method: Mapping[str, Any], components: Mapping[str, Any]) -> list[str]:
    """The components (their config names, in key order) a method's block names: every value of its keys
    but ``label``, ``kind`` and ``settings`` that is the name of a configured component."""
    out = []
    for key, value in method.items():
        if key not in NOT_COMPONENT_KEYS and isinstance(value, str) and value in components and value not in out:
            out.append(value)
    return out


#: The fixed source of a method key that reads the test configurations' own task grasps (their contact maps).
GROUND_TRUTH = "ground_truth"
#: Method kinds whose predictions are the test configurations' own task grasps (the Dataset row).
GROUND_TRUTH_KINDS = ("reference",)


def reads_ground_truth(name: str, methods: Mapping[str, Mapping[str, Any]]) -> bool:
    """Whether method ``name`` (a key of ``methods``, the config's block) needs the test configurations'
    ground-truth task grasps: a kind of :data:`GROUND_TRUTH_KINDS`, a key set to :data:`GROUND_TRUTH`, or a
    method it is ``of`` (kind filtered) that does."""
    block = methods[name]
    if block["kind"] in GROUND_TRUTH_KINDS:
        return True
    if any(v == GROUND_TRUTH for k, v in block.items() if k not in NOT_COMPONENT_KEYS):
        return True
    return "of" in block and reads_ground_truth(block["of"], methods)
