"""docs/formats.md describes the prediction store as the code writes it: its table of arrays is read here and
compared with the layout of tohgs/data/predictions.py (names, dtypes, dimension names) and with a store
written and read back (shapes)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from tohgs.data import predictions

REPO = Path(__file__).resolve().parent.parent
DOC = REPO / "docs" / "formats.md"


def _documented() -> dict[str, dict[str, str]]:
    rows = {}
    for line in DOC.read_text().splitlines():
        m = re.match(r"^\| `([a-z_]+)` \| (\w+) \| ([a-z_, ]+) \| (\([^)]*\)) \|", line)
        if m:
            rows[m.group(1)] = {"dtype": m.group(2), "dims": m.group(3), "shape": m.group(4)}
    return rows


def test_the_documented_arrays_are_the_stores():
    doc = _documented()
    code = predictions.LAYOUT.arrays
    assert list(doc) == list(code), "docs/formats.md lists other arrays than tohgs/data/predictions.py"
    for name, (dims, dtype) in code.items():
        assert doc[name]["dtype"] == np.dtype(dtype).name, name
        assert tuple(d.strip() for d in doc[name]["dims"].split(",")) == dims, name
        assert doc[name]["shape"].count(",") + (0 if doc[name]["shape"].endswith(",)") else 1) == len(dims), name


def test_a_store_written_as_documented_reads_back(tmp_path):
    c, s, n = 2, 3, 5
    sizes = {"C": c, "S": s, "N": n, "51": 51}
    arrays = {}
    for name, row in _documented().items():
        shape = tuple(sizes[k.strip()] for k in row["shape"].strip("()").split(",") if k.strip())
        arrays[name] = np.zeros(shape, dtype=row["dtype"]) if row["dtype"] != "bool" else np.ones(shape, bool)
    arrays["object_id"][:] = [0, 1]
    path = tmp_path / "p.zarr"
    predictions.write_predictions(arrays, {"task": "placing", "method": "m", "objects": ["a", "b"]}, path)
    back, attrs = predictions.read_predictions(path)
    for name, a in arrays.items():
        assert back[name].shape == a.shape and back[name].dtype == a.dtype, name
    assert attrs["objects"][int(back["object_id"][1])] == "b"
    arrays["grasp_goal"][0, 0, 0] = np.nan  # documented: every grasp is finite
    bad = tmp_path / "bad.zarr"
    with pytest.raises(ValueError, match="non-finite"):
        predictions.write_predictions(arrays, {"task": "placing", "method": "m", "objects": ["a", "b"]}, bad)
        predictions.read_predictions(bad)
