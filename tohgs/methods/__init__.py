"""Methods: how a method's components compose into grasps for the test configurations.

A method is a config block under ``methods`` (:file:`config/README.md`): a ``label`` (its row name in the
tables), a ``kind`` and the kind's keys, which name components (``components.<name>``), another method or
fixed sources (``ground_truth``). Kind ``k`` is the class ``METHOD`` of ``tohgs.methods.<k>``
(:class:`tohgs.methods.base.Method`; or of a module registered by :func:`register_method_kind`) and its
declaration, the schema block ``$defs.method_kinds.<k>`` (:func:`kind_declarations`: its keys and what each
names, whether it reads ground truth, its settings), which everything here reads; one rule predicts any
method (:func:`tohgs.methods.predict.predict`) into ``results/predictions/<task>/<method>.zarr``.

This module is read at workflow parse time, so it imports neither torch nor the method modules.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tohgs.kinds import KIND, kind_modules, schema_defs

_METHODS_DIR = Path(__file__).resolve().parent
NOT_COMPONENT_KEYS = ("label", "kind", "settings")  # method keys that never name a component
#: The prediction settings every job reads, whatever its kind (:class:`tohgs.methods.base.SamplingSettings`; a
#: kind's own are listed under ``$defs.method_kinds.<kind>.settings`` in the schema).
SAMPLING_KEYS = ("samples", "seed", "threads", "device", "chunk")
#: Method kinds defined outside this package, by name: their modules and schema blocks (:func:`register_method_kind`).
_REGISTERED: dict[str, tuple[str, dict[str, Any]]] = {}


def register_method_kind(kind: str, module: str, declaration: Mapping[str, Any]) -> None:
    """Make ``kind`` the method kind whose ``METHOD`` is in the module ``module`` (dotted, importable) and whose
    schema block is ``declaration`` (what ``$defs.method_kinds.<kind>`` holds for a kind of this package:
    :func:`tohgs.config.load_schema` adds it there), for a kind defined outside this package (a test's, a
    user's).

    Raises:
        ValueError: ``kind`` is not a module-like name, or is a kind of this package.
    """
    if not KIND.fullmatch(kind) or kind in kind_modules(_METHODS_DIR, "METHOD"):
        raise ValueError(f"method kind {kind!r}: not a name of the form {KIND.pattern}, or a kind of tohgs.methods")
    _REGISTERED[kind] = (module, dict(declaration))


def method_module(kind: str) -> str:
    """The module (dotted) whose ``METHOD`` is kind ``kind``'s."""
    return _REGISTERED[kind][0] if kind in _REGISTERED else f"tohgs.methods.{kind}"


def registered_declarations() -> dict[str, dict[str, Any]]:
    """The schema blocks of the kinds registered by :func:`register_method_kind`, by kind (copies)."""
    return {k: dict(decl) for k, (_, decl) in _REGISTERED.items()}


def kind_declarations() -> dict[str, dict[str, Any]]:
    """Every method kind's schema block, by kind: the schema file's ``$defs.method_kinds`` and the registered
    kinds' (:func:`register_method_kind`). A block holds ``keys`` (each method key the kind takes: the
    ``role`` of what it names, a component's role or ``method``, its ``fixed`` sources and a
    ``description``), ``settings``, ``blocks`` and ``reads_ground_truth`` (its predictions are the
    configurations' own task grasps)."""
    return {**schema_defs("method_kinds"), **registered_declarations()}


def method_kinds() -> list[str]:
    """Every method kind: a module of this package that binds ``METHOD`` (read as text), and the registered."""
    return sorted({*kind_modules(_METHODS_DIR, "METHOD"), *_REGISTERED})


def method_keys(declaration: Mapping[str, Any], role: str) -> list[str]:
    """The keys of a kind's schema block (``$defs.method_kinds.<kind>``) that name a ``role``: ``method`` for
    the keys that name another method (whose predictions the kind reads; at most one)."""
    return [k for k, spec in declaration.get("keys", {}).items() if spec.get("role") == role]


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


def base_method(name: str, methods: Mapping[str, Mapping[str, Any]],
                kinds: Mapping[str, Mapping[str, Any]] | None = None) -> str | None:
    """The method whose predictions method ``name`` reads (the value of its kind's key of role ``method``:
    F-GraspTTA's ``of``), or None. ``kinds``: the kinds' schema blocks (default :func:`kind_declarations`)."""
    kinds = kind_declarations() if kinds is None else kinds
    keys = method_keys(kinds[methods[name]["kind"]], "method")
    return methods[name].get(keys[0]) if keys else None


def of_chain(name: str, methods: Mapping[str, Mapping[str, Any]],
             kinds: Mapping[str, Mapping[str, Any]] | None = None) -> list[str]:
    """Method ``name`` and the methods it reads the predictions of (:func:`base_method`), in turn:
    ``["f-grasptta", "grasptta"]``. ``kinds``: the kinds' schema blocks (default :func:`kind_declarations`).

    Raises:
        ValueError: the chain comes back to a method already in it (the message shows the cycle).
    """
    kinds = kind_declarations() if kinds is None else kinds
    chain = [name]
    while (base := base_method(chain[-1], methods, kinds)) is not None:
        if base in chain:
            raise ValueError(f"a cycle of methods ({' -> '.join([*chain, base])})")
        chain.append(base)
    return chain


#: The fixed source of a method key that reads the test configurations' own task grasps (their contact maps).
GROUND_TRUTH = "ground_truth"
#: The fixed source of a method's ``contact`` key for a generator that reads no contact map.
NO_CONTACT = "none"


def reads_ground_truth(name: str, methods: Mapping[str, Mapping[str, Any]],
                       kinds: Mapping[str, Mapping[str, Any]] | None = None) -> bool:
    """Whether method ``name`` (a key of ``methods``, the config's block) needs the test configurations'
    ground-truth task grasps: it or a method it reads (:func:`of_chain`) is of a kind whose schema block says
    ``reads_ground_truth``, or sets a key to :data:`GROUND_TRUTH` where its kind allows that source.
    ``kinds``: the kinds' schema blocks (default :func:`kind_declarations`)."""
    kinds = kind_declarations() if kinds is None else kinds

    def reads(m: str) -> bool:
        decl = kinds[methods[m]["kind"]]
        return bool(decl.get("reads_ground_truth")) or any(
            methods[m].get(k) == GROUND_TRUTH and GROUND_TRUTH in spec.get("fixed", [])
            for k, spec in decl.get("keys", {}).items())

    return any(reads(m) for m in of_chain(name, methods, kinds))
