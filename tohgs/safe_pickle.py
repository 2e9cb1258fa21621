"""The one restricted unpickler: reads a pickle of plain data without ever running code from it.

A pickle names the globals (module, name) it builds its objects with; :func:`restricted_loads` resolves only
the ones on its caller's explicit allow-list, may hand out inert stand-in classes its caller defines (MANO's
chumpy and scipy.sparse objects), and refuses every other global with :class:`UnsafePickleError`, so a
malicious pickle (``os.system`` in a ``__reduce__``) is refused before anything runs. Callers:
:mod:`tohgs.hand.mano_backend` (a user's ``MANO_RIGHT.pkl``) and :mod:`tohgs.official.format` (the official
dataset's ``.npy`` grasp files). A leaf module: it imports nothing of tohgs.
"""

from __future__ import annotations

import importlib
import io
import pickle
from collections.abc import Callable, Collection
from typing import Any

#: numpy's array, dtype and scalar constructors, old (``numpy.core``) and new (``numpy._core``) spellings: what
#: a pickle of numpy arrays and numpy scalars names. The base of every caller's allow-list.
NUMPY_GLOBALS = frozenset({
    ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
    ("numpy", "ndarray"), ("numpy", "dtype"), ("numpy.core.multiarray", "scalar"),
    ("numpy._core.multiarray", "scalar"),
})

#: A caller's stand-ins: ``(module, name)`` -> an inert class to build in place of that global, or None.
StandIns = Callable[[str, str], "type | None"]


class UnsafePickleError(pickle.UnpicklingError):
    """The pickle names a global that is not on its reader's allow-list."""


class _RestrictedUnpickler(pickle.Unpickler):
    """Resolves the allow-listed globals by import, the stand-ins' by the caller's function; refuses the rest."""

    def __init__(self, file: io.BytesIO, allowed: Collection[tuple[str, str]], stand_ins: StandIns | None,
                 allowed_text: str) -> None:
        super().__init__(file, encoding="latin1")
        self._allowed, self._stand_ins, self._allowed_text = allowed, stand_ins, allowed_text

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in self._allowed:
            return getattr(importlib.import_module(module), name)
        stand_in = self._stand_ins(module, name) if self._stand_ins is not None else None
        if stand_in is not None:
            return stand_in
        raise UnsafePickleError(f"refusing global '{module}.{name}' ({self._allowed_text})")


def restricted_loads(data: bytes, source: str, allowed: Collection[tuple[str, str]], *,
                     stand_ins: StandIns | None = None, allowed_text: str = "only numpy arrays are allowed",
                     kind: str = "pickle") -> Any:
    """Unpickle ``data`` (Python 2 pickles too: ``latin1`` strings) building only allow-listed globals.

    Args:
        data: the pickle's bytes.
        source: what the bytes are (a file's path), named first in every error.
        allowed: the ``(module, name)`` globals the pickle may name (the caller's explicit list, usually
            :data:`NUMPY_GLOBALS` and a few more); each is imported as it is named.
        stand_ins: for a global not in ``allowed``, the caller's inert class to build in its place (a class
            defined by the caller, never imported from the pickle's module), or None to refuse it.
        allowed_text: what is allowed, in words, for the refusal's message.
        kind: what the bytes should be, for the message of an unreadable pickle (``MANO pickle``).

    Raises:
        ValueError: ``"<source>: refusing global '<module>.<name>' (<allowed_text>)"`` for a global neither
            allowed nor stood in for (nothing of the pickle has run), or ``"<source>: not a readable <kind>
            (...)"`` for a damaged or truncated pickle.
    """
    try:
        return _RestrictedUnpickler(io.BytesIO(data), allowed, stand_ins, allowed_text).load()
    except UnsafePickleError as exc:
        raise ValueError(f"{source}: {exc}") from exc
    except Exception as exc:
        raise ValueError(f"{source}: not a readable {kind} ({type(exc).__name__}: {exc})") from exc
