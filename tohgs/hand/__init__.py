"""The hand: one MANO-layout interface, two backends (the open ``anny`` hand, a user's MANO file).

>>> hand = load_hand("anny")                      # doctest: +SKIP
>>> out = hand(torch.zeros(8, 51))                # vertices (8, V, 3), joints (8, 21, 3), metres
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from tohgs.hand.assets import HandAssets

if TYPE_CHECKING:
    from tohgs.hand.model import HandModel, HandOutput

__all__ = ["HandAssets", "HandModel", "HandOutput", "load_hand", "load_hand_assets"]


def __getattr__(name: str):
    """``HandModel`` and ``HandOutput`` load torch on first use, so torch-free jobs can read hand assets."""
    if name in ("HandModel", "HandOutput"):
        from tohgs.hand import model

        return getattr(model, name)
    raise AttributeError(f"module 'tohgs.hand' has no attribute {name!r}")


def load_hand_assets(model: str = "anny", mano_path: str | Path | None = None,
                     cache_dir: str | Path | None = None) -> HandAssets:
    """The assets of backend ``model`` (``anny`` or ``mano``; ``mano`` needs ``mano_path``)."""
    if model == "anny":
        from tohgs.hand.anny_backend import load_anny_assets

        return load_anny_assets(cache_dir)
    if model == "mano":
        from tohgs.hand.mano_backend import load_mano_assets

        if mano_path is None:
            raise ValueError("hand.model is 'mano' but hand.mano_path is not set")
        return load_mano_assets(mano_path)
    raise ValueError(f"unknown hand model '{model}' (expected 'anny' or 'mano')")


def load_hand(model: str = "anny", mano_path: str | Path | None = None, cache_dir: str | Path | None = None,
              device: str = "cpu") -> HandModel:
    """A ready :class:`HandModel` of backend ``model`` on ``device``."""
    from tohgs.hand.model import HandModel

    return HandModel(load_hand_assets(model, mano_path, cache_dir)).to(device)
