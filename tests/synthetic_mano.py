"""A small synthetic MANO_RIGHT.pkl for tests: MANO's format (numpy arrays, a scipy sparse J_regressor,
chumpy objects), built on the anny hand's geometry. Never a real MANO file."""

from __future__ import annotations

import pickle
import sys
import types
from pathlib import Path

import numpy as np
import scipy.sparse as sp


def _chumpy_class():
    """A class that pickles as chumpy.ch.Ch (the module is registered only while pickling)."""
    mod = sys.modules.get("chumpy.ch") or types.ModuleType("chumpy.ch")
    if not hasattr(mod, "Ch"):
        class Ch:  # noqa: D401 - mimics chumpy's Ch: its array lives in the 'x' attribute
            def __init__(self, x):
                self.x = x
        Ch.__module__ = "chumpy.ch"
        Ch.__qualname__ = "Ch"
        mod.Ch = Ch
    return mod


def make_synthetic_mano(assets, path: Path, seed: int = 0) -> dict:
    """Write a MANO-format pickle whose arrays come from ``assets`` (HandAssets); returns the arrays."""
    rng = np.random.default_rng(seed)
    v = assets.rest_vertices
    n = len(v)
    # Joint regressor: for each joint an affine combination of its 4 nearest vertices that reproduces it.
    rows, cols, vals = [], [], []
    for k, j in enumerate(assets.rest_joints):
        ids = np.argsort(np.linalg.norm(v - j, axis=1))[:12]
        a = np.vstack([v[ids].T, np.ones(len(ids))])
        w = np.linalg.lstsq(a, np.r_[j, 1.0], rcond=None)[0]
        rows += [k] * len(ids)
        cols += ids.tolist()
        vals += w.tolist()
    jreg = sp.csc_matrix((vals, (rows, cols)), shape=(16, n))
    arrays = {
        "v_template": v.copy(),
        "shapedirs": assets.shape_dirs.copy(),
        "posedirs": rng.normal(0, 1e-3, size=(n, 3, 135)),
        "J_regressor": jreg,
        "weights": assets.weights.copy(),
        "f": assets.faces.astype(np.uint32),
        "kintree_table": np.array([[4294967295, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14], list(range(16))]),
        "bs_type": "lrotmin",
        "bs_style": "lbs",
    }
    mod = _chumpy_class()
    sys.modules.setdefault("chumpy", types.ModuleType("chumpy"))
    sys.modules["chumpy.ch"] = mod
    try:
        payload = dict(arrays)
        payload["shapedirs"] = mod.Ch(arrays["shapedirs"])
        payload["J"] = mod.Ch(jreg @ v)
        path.write_bytes(pickle.dumps(payload, protocol=2))
    finally:
        sys.modules.pop("chumpy.ch", None)
        sys.modules.pop("chumpy", None)
    return arrays
