"""A user-supplied MANO model (``MANO_RIGHT.pkl``), read safely, skinned by tohgs's own LBS.

The MANO file is licence-restricted: tohgs never ships or downloads it. A user who has one points
``hand.mano_path`` at it. The file is a Python-2 pickle of numpy arrays, a scipy sparse matrix
(``J_regressor``) and chumpy objects; it is read with the restricted unpickler (:mod:`tohgs.safe_pickle`),
which builds numpy arrays and scipy sparse matrices only, turns chumpy objects into plain arrays (their ``x``
value) and refuses every other global, so a malicious pickle cannot run code.

MANO's equations (Romero et al. 2017): ``T(beta, theta) = v_template + S beta + P (R(theta) - I)``,
joints ``J = J_regressor T(beta)`` (linear in beta), then linear blend skinning; the template is the flat
hand (``flat_hand_mean=True``) in the canonical frame, so it is used as it is.
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.hand.assets import HandAssets
from tohgs.hand.layout import FINGER_POSE_DIM
from tohgs.safe_pickle import NUMPY_GLOBALS, restricted_loads

#: Globals a MANO pickle may name (:func:`tohgs.safe_pickle.restricted_loads`' allow-list): numpy's, and
#: Python 2's ``copyreg._reconstructor(cls, object, state)``, safe here because every class it can receive
#: comes from this list or the stand-ins; protocol-2 pickles written by Python 3 carry bytes as
#: ``_codecs.encode(str, 'latin1')``, a pure function.
MANO_GLOBALS = NUMPY_GLOBALS | {("copyreg", "_reconstructor"), ("builtins", "object"), ("_codecs", "encode")}
_SPARSE_CLASSES = {"csc_matrix", "csr_matrix", "coo_matrix"}


class _ChumpyStub:
    """Stands in for any chumpy object: keeps its state so that its array value can be read."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.state: Any = None

    def __setstate__(self, state: Any) -> None:
        self.state = state

    def value(self) -> np.ndarray:
        st = self.state
        if isinstance(st, dict):
            for key in ("x", "_x", "a"):
                if key in st:
                    v = st[key]
                    return v.value() if isinstance(v, _ChumpyStub) else np.asarray(v)
        raise pickle.UnpicklingError("a chumpy object without an array value ('x')")


class _SparseStub:
    """Stands in for a scipy sparse matrix: rebuilt from its pickled attributes (``kind`` per subclass)."""

    kind = "csc_matrix"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.state: dict[str, Any] = {}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.state = state

    def toarray(self) -> np.ndarray:
        import scipy.sparse as sp

        st = self.state
        shape = tuple(st.get("_shape", st.get("shape")))
        if self.kind == "coo_matrix":
            return sp.coo_matrix((st["data"], (st["row"], st["col"])), shape=shape).toarray()
        cls = sp.csc_matrix if self.kind == "csc_matrix" else sp.csr_matrix
        return cls((st["data"], st["indices"], st["indptr"]), shape=shape).toarray()


_SPARSE_STUBS = {k: type(f"_{k}_stub", (_SparseStub,), {"kind": k}) for k in _SPARSE_CLASSES}


def _stand_in(module: str, name: str) -> type | None:
    """The inert class built in place of a scipy sparse matrix or any chumpy object (None: refused)."""
    if module.startswith("scipy.sparse") and name in _SPARSE_CLASSES:
        return _SPARSE_STUBS[name]
    if module == "chumpy" or module.startswith("chumpy."):
        return _ChumpyStub
    return None


def _plain(v: Any) -> Any:
    if isinstance(v, _ChumpyStub):
        return v.value()
    if isinstance(v, _SparseStub):
        return v.toarray()
    return v


def read_mano_pickle(path: str | Path) -> dict[str, Any]:
    """Read a MANO model file safely into a dict of numpy arrays (and plain values).

    Raises:
        FileNotFoundError: no such file (the message names it).
        ValueError: not a MANO pickle, or a refused global (the message names the file and the problem).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"hand.mano_path: '{path}' does not exist (supply your own MANO_RIGHT.pkl)")
    obj = restricted_loads(path.read_bytes(), str(path), MANO_GLOBALS, stand_ins=_stand_in,
                           allowed_text="only numpy, scipy.sparse and chumpy are allowed", kind="MANO pickle")
    if not isinstance(obj, dict):
        raise ValueError(f"{path}: expected a dict at the top of the MANO pickle, got {type(obj).__name__}")
    return {k: _plain(v) for k, v in obj.items()}


def mano_assets_from_dict(d: dict[str, Any], source: str = "MANO model") -> HandAssets:
    """MANO arrays -> :class:`HandAssets` (all derived parts filled in)."""
    from tohgs.hand.derived import complete_assets

    required = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "f")
    missing = [k for k in required if k not in d]
    if missing:
        raise ValueError(f"{source}: missing keys {missing}")
    v = np.asarray(d["v_template"], dtype=np.float64)
    n = len(v)
    shapedirs = np.asarray(d["shapedirs"], dtype=np.float64)[..., :10]
    posedirs = np.asarray(d["posedirs"], dtype=np.float64)
    jreg = np.asarray(d["J_regressor"].toarray() if hasattr(d["J_regressor"], "toarray") else d["J_regressor"],
                      dtype=np.float64)
    weights = np.asarray(d["weights"], dtype=np.float64)
    faces = np.asarray(d["f"], dtype=np.int64)
    expect = {"v_template": (v.shape, (n, 3)), "shapedirs": (shapedirs.shape, (n, 3, 10)),
              "posedirs": (posedirs.shape, (n, 3, 135)), "J_regressor": (jreg.shape, (16, n)),
              "weights": (weights.shape, (n, 16))}
    for key, (got, want) in expect.items():
        if got != want:
            raise ValueError(f"{source}: '{key}' has shape {got}, expected {want}")
    assets = HandAssets(
        name="mano", rest_vertices=v, shape_dirs=shapedirs, pose_dirs=posedirs, rest_joints=jreg @ v,
        joint_shape_dirs=np.einsum("jv,vcl->jcl", jreg, shapedirs), weights=weights, faces=faces,
        closed_faces=faces, part_labels=np.zeros(n, dtype=np.int64), tip_ids=np.zeros(5, dtype=np.int64),
        contact_ids=np.zeros(0, dtype=np.int64), joint_limits=np.zeros((15, 3, 2)), prior_mean=np.zeros(FINGER_POSE_DIM),
        prior_std=np.ones(FINGER_POSE_DIM), meta={"backend": "mano", "source": source},
    )
    return complete_assets(assets)


def load_mano_assets(path: str | Path) -> HandAssets:
    """Read ``MANO_RIGHT.pkl`` at ``path`` into :class:`HandAssets`."""
    return mano_assets_from_dict(read_mano_pickle(path), str(path))
