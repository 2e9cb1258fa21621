"""Methods: how a method's components compose into grasps for the test configurations.

A method is a config block under ``methods`` (:file:`config/README.md`): a ``label`` (its row name in the
tables), a ``kind`` and the kind's keys, which name components (``components.<name>``) or fixed sources
(``ground_truth``). Kind ``k`` is the class ``METHOD`` of ``tohgs.methods.<k>``
(:class:`tohgs.methods.base.Method`; or of a module registered by :func:`register_method_kind`); one rule
predicts any method (:func:`tohgs.methods.predict.predict`) into ``results/predictions/<task>/<method>.zarr``.

This module is read at workflow parse time, so it imports neither torch nor the method modules.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tohgs.kinds import KIND, kind_modules

_METHODS_DIR = Path(__file__).resolve().parent
NOT_COMPONENT_KEYS = ("label", "kind", "settings")  # method keys that never name a component
#: The prediction settings every job reads, whatever its kind (:class:`tohgs.methods.base.SamplingSettings`; a
#: kind's own are listed under ``$defs.method_kinds.<kind>.settings`` in the schema).
SAMPLING_KEYS = ("samples", "seed", "threads", "device", "chunk")
#: Method kinds defined outside this package, by name: their modules (:func:`register_method_kind`).
_REGISTERED: dict[str, str] = {}


def register_method_kind(kind: str, module: str) -> None:
    """Make ``kind`` the method kind whose ``METHOD`` is in the module ``module`` (dotted, importable), for a
    kind defined outside this package (a test's, a user's); its schema block is added to the schema
    (``$defs.method_kinds.<kind>``) by whoever validates with it.

    Raises:
        ValueError: ``kind`` is not a module-like name, or is a kind of this package.
    """
    if not KIND.fullmatch(kind) or kind in kind_modules(_METHODS_DIR, "METHOD"):
        raise ValueError(f"method kind {kind!r}: not a name of the form {KIND.pattern}, or a kind of tohgs.methods")
    _REGISTERED[kind] = module


def method_module(kind: str) -> str:
    """The module (dotted) whose ``METHOD`` is kind ``kind``'s."""
    return _REGISTERED.get(kind, f"tohgs.methods.{kind}")


def method_kinds() -> list[str]:
    """Every method kind: a module of this package that binds ``METHOD`` (read as text), and the registered."""
    return sorted({*kind_modules(_METHODS_DIR, "METHOD"), *_REGISTERED})


def method_kind_exists(kind: str) -> bool:
    """Whether ``kind`` is a method kind (:func:`method_kinds`; ``base`` and ``predict`` are not)."""
    return kind in method_kinds()


def method_components(method: Mapping[str, Any], components: Mapping[str, Any]) -> list[str]:
    """The components (their config names, in key order) a method's block names: every value of its keys
    but ``label``, ``kind`` and ``settings`` that is the name of a configured component."""
    out = []
    for key, value in method.items():
        if key not in NOT_COMPONENT_KEYS and isinstance(value, str) and value in components and value not in out:
            out.append(value)
    return out


def of_chain(name: str, methods: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Method ``name`` and the methods it is ``of`` (kind ``filtered``), in turn: ``["f-grasptta", "grasptta"]``.

    Raises:
        ValueError: the chain comes back to a method already in it (the message shows the cycle).
    """
    chain = [name]
    while (base := methods[chain[-1]].get("of")) is not None:
        if base in chain:
            raise ValueError(f"a cycle of methods ({' -> '.join([*chain, base])})")
        chain.append(base)
    return chain


#: The fixed source of a method key that reads the test configurations' own task grasps (their contact maps).
GROUND_TRUTH = "ground_truth"
#: The fixed source of a method's ``contact`` key for a generator that reads no contact map.
NO_CONTACT = "none"
#: Method kinds whose predictions are the test configurations' own task grasps (the Dataset row).
GROUND_TRUTH_KINDS = ("reference",)


def reads_ground_truth(name: str, methods: Mapping[str, Mapping[str, Any]]) -> bool:
    """Whether method ``name`` (a key of ``methods``, the config's block) needs the test configurations'
    ground-truth task grasps: it or a method it is ``of`` (:func:`of_chain`) is of a kind of
    :data:`GROUND_TRUTH_KINDS` or has a key set to :data:`GROUND_TRUTH`."""
    return any(methods[m]["kind"] in GROUND_TRUTH_KINDS
               or any(v == GROUND_TRUTH for k, v in methods[m].items() if k not in NOT_COMPONENT_KEYS)
               for m in of_chain(name, methods))
