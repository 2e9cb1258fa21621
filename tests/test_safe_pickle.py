"""The one restricted unpickler (tohgs/safe_pickle.py) and its two callers' allow-lists: the MANO reader's
(tohgs/hand/mano_backend.py) and the official dataset's (tohgs/official/format.py). A pickle that names a
global off its caller's list is refused before any of it runs."""

from __future__ import annotations

import copyreg
import pickle
import subprocess

import numpy as np
import pytest

from tohgs.hand.mano_backend import MANO_GLOBALS, read_mano_pickle
from tohgs.official.format import OFFICIAL_GLOBALS, load_official_pickle
from tohgs.safe_pickle import NUMPY_GLOBALS, restricted_loads


class _Calls:
    """Pickles as a call of ``func(*args)``: the payload of a malicious pickle (pickling runs nothing)."""

    def __init__(self, func, *args) -> None:
        self.func, self.args = func, args

    def __reduce__(self):
        return self.func, self.args


@pytest.mark.parametrize("payload", [_Calls(eval, "1"), _Calls(subprocess.call, ["true"]),
                                     _Calls(__import__, "os")])
def test_every_caller_refuses_code(tmp_path, payload):
    data = pickle.dumps({"a": np.arange(3.0), "evil": payload})
    with pytest.raises(ValueError, match=r"x\.pkl: refusing global '(builtins|subprocess)\."):
        restricted_loads(data, "x.pkl", NUMPY_GLOBALS)
    with pytest.raises(ValueError, match=r"x\.npy: refusing global .*only numpy arrays and plain containers"):
        load_official_pickle(data, "x.npy")
    (tmp_path / "MANO_RIGHT.pkl").write_bytes(data)
    with pytest.raises(ValueError, match=r"MANO_RIGHT\.pkl: refusing global .*numpy, scipy\.sparse and chumpy"):
        read_mano_pickle(tmp_path / "MANO_RIGHT.pkl")


def test_each_caller_has_its_own_allow_list():
    """Python 2's object reconstruction (copyreg._reconstructor) is MANO's, not the official dataset's; both
    build numpy arrays; a stand-in serves only the caller that names it."""
    assert NUMPY_GLOBALS < MANO_GLOBALS and NUMPY_GLOBALS < OFFICIAL_GLOBALS
    assert ("copyreg", "_reconstructor") in MANO_GLOBALS and ("copyreg", "_reconstructor") not in OFFICIAL_GLOBALS
    data = pickle.dumps(_Calls(copyreg._reconstructor, object, object, None))
    with pytest.raises(ValueError, match="refusing global 'copyreg._reconstructor'"):
        load_official_pickle(data, "x.npy")
    arrays = {"a": np.arange(6.0).reshape(2, 3), "s": np.float32(2.5), "names": ["can", "mug"]}
    back = load_official_pickle(pickle.dumps(arrays, protocol=2), "ok.npy")
    assert np.array_equal(back["a"], arrays["a"]) and back["s"] == np.float32(2.5) and back["names"] == ["can", "mug"]

    class StandIn(dict):
        """The caller's inert class: a plain dict."""

    od = pickle.dumps(__import__("collections").OrderedDict(a=1))
    with pytest.raises(ValueError, match="refusing global 'collections.OrderedDict'"):
        restricted_loads(od, "od.pkl", NUMPY_GLOBALS)
    stood_in = restricted_loads(od, "od.pkl", NUMPY_GLOBALS,
                                stand_ins=lambda m, n: StandIn if (m, n) == ("collections", "OrderedDict") else None)
    assert isinstance(stood_in, StandIn) and stood_in == {"a": 1}


def test_a_damaged_pickle_is_named_and_unreadable():
    data = pickle.dumps({"a": np.arange(3.0)})
    with pytest.raises(ValueError, match=r"cut\.pkl: not a readable MANO pickle"):
        restricted_loads(data[: len(data) // 2], "cut.pkl", MANO_GLOBALS, kind="MANO pickle")
