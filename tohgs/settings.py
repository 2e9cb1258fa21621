"""Settings blocks, a leaf module: a frozen settings dataclass from its config mapping, and the one merge of
nested config mappings.

The library's modules build their settings here, not in :mod:`tohgs.config`: that module (the validator,
the schema, the method and component registries) is the workflow's, and a module that imported it would
make every job that runs the module stale when a schema check changes (:mod:`tohgs.code_inputs`).
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

T = TypeVar("T")


def settings_from(cls: type[T], values: Mapping[str, Any] | None, *, complete: bool = False,
                  where: str | None = None) -> T:
    """An instance of the frozen settings dataclass ``cls`` from a config mapping; YAML lists become tuples.

    Args:
        cls: the dataclass.
        values: its settings (None: none).
        complete: every field must be given (but a :func:`block` marked optional): a missing key is an error,
            not the dataclass's default (a job's settings come from the validated config, where every key has
            its schema default).
        where: what the settings are of, for the errors (default ``cls``'s name).

    Raises:
        ValueError: a key ``cls`` does not have, or (``complete``) one it has that ``values`` lacks; the
            message names them.
    """
    values = dict(values or {})
    fields = dataclasses.fields(cls)
    names = [f.name for f in fields]
    what = where or cls.__name__
    unknown = set(values) - set(names)
    if unknown:
        raise ValueError(f"{what}: unknown settings {sorted(unknown)} (its settings: {', '.join(names)})")
    missing = [f.name for f in fields if f.name not in values and not f.metadata.get("optional")]
    if complete and missing:
        raise ValueError(f"{what}: settings {missing} missing (a job is given every setting its kind reads)")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def merge(dst: dict[str, Any], src: Mapping[str, Any], *, overwrite: bool = True) -> dict[str, Any]:
    """Merge ``src`` into ``dst`` in place, recursively into the mappings both have, and return ``dst``.

    ``overwrite``: ``src``'s value wins where both have a key (an overlay: a method's ``settings`` over the
    ``prediction`` block, ``--config`` overrides); otherwise ``dst``'s does and only the keys it lacks are
    added (the schema's default entries under a config's). ``src``'s values are deep-copied, and the keys
    ``dst`` has keep their order.
    """
    for k, v in src.items():
        if isinstance(v, Mapping) and isinstance(dst.get(k), dict):
            merge(dst[k], v, overwrite=overwrite)
        elif overwrite or k not in dst:
            dst[k] = copy.deepcopy(v)
    return dst


def block(cls: type, *, optional: bool = False) -> Any:
    """A field of a settings dataclass that is a settings block of its own (a method kind's ``tta``,
    ``filter``): its default is ``cls()``, and :func:`build_blocks` turns a mapping given for it into ``cls``.
    ``optional``: :func:`settings_from` with ``complete`` lets it be missing (the block's defaults then)."""
    return dataclasses.field(default_factory=cls, metadata={"block": cls, "optional": optional})


def build_blocks(settings: Any) -> None:
    """Turn, in place, each mapping a :func:`block` field of the frozen dataclass instance ``settings`` holds
    into its dataclass (call it from ``__post_init__``).

    Raises:
        ValueError: a key the block's dataclass does not have (named with the block).
    """
    for f in dataclasses.fields(settings):
        cls, value = f.metadata.get("block"), getattr(settings, f.name)
        if cls is not None and not isinstance(value, cls):
            object.__setattr__(settings, f.name, settings_from(cls, value, where=f"settings block {f.name!r}"))
