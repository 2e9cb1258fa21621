"""Prior-grasp stores: ``results/grasps/prior/<object>.zarr`` (and the unfiltered ``raw/<object>.zarr``).

Zarr v3, one row per optimised grasp (B of them), in the object's mesh frame:

=====================  ==========  ==================  ===================================================
array                  shape       dimension_names     meaning
=====================  ==========  ==================  ===================================================
pose                   (B, 51)     grasp, param        translation (m), global axis-angle, 45 finger params
contact_idx            (B, n)      grasp, contact      the optimiser's contacts, indices into the hand's candidates
plane                  (B, 4)      grasp, plane        support plane [nx, ny, nz, offset] (zeros: none)
energy_<term>          (B,)        grasp               final optimiser energies (total, fc, dis, pen, ...)
pv                     (B,)        grasp               penetration volume, m^3
sd                     (B,)        grasp               simulation displacement, m
contact_distance       (B,)        grasp               smallest signed hand-object distance, m
pass_<check>, passed   (B,)        grasp               filter flags (filtered stores only)
=====================  ==========  ==================  ===================================================

Root attributes: ``schema``, ``schema_version``, ``manifest`` (:mod:`tohgs.data.store`), ``object``, ``hand`` (the model's name), ``seed``,
``config`` (the settings that made it), ``timing`` (seconds per phase) and, in filtered stores,
``thresholds`` and ``rejections`` (counts by check).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.data.store import read_store, write_store
from tohgs.hand.layout import GRASP_DIM

SCHEMA = "tohgs.prior_grasps"
SCHEMA_VERSION = 1
ENERGY_TERMS = ("total", "fc", "dis", "pen", "prior", "spen", "joint", "plane")
METRICS = ("pv", "sd", "contact_distance")


@dataclass
class PriorGrasps:
    """The optimised grasps of one object (arrays as in the module table)."""

    object: str
    pose: np.ndarray
    contact_idx: np.ndarray
    plane: np.ndarray
    energies: dict[str, np.ndarray]
    pv: np.ndarray
    sd: np.ndarray
    contact_distance: np.ndarray
    flags: dict[str, np.ndarray] | None = None
    attrs: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.pose)

    @property
    def passed(self) -> np.ndarray:
        """(B,) bool, the filter's verdict (raises if the store is unfiltered)."""
        if self.flags is None:
            raise ValueError(f"prior grasps of {self.object} are not filtered yet")
        return self.flags["passed"]

    def validate(self, source: str = "prior grasps") -> None:
        """Check shapes, dtypes and finiteness; raises ``ValueError`` naming ``source``."""
        b = len(self.pose)
        if self.pose.shape != (b, GRASP_DIM):
            raise ValueError(f"{source}: array 'pose' has shape {self.pose.shape}, expected ({b}, {GRASP_DIM})")
        if self.contact_idx.ndim != 2 or len(self.contact_idx) != b:
            raise ValueError(f"{source}: array 'contact_idx' has shape {self.contact_idx.shape}, expected ({b}, n)")
        if self.plane.shape != (b, 4):
            raise ValueError(f"{source}: array 'plane' has shape {self.plane.shape}, expected ({b}, 4)")
        missing = set(ENERGY_TERMS) - set(self.energies)
        if missing:
            raise ValueError(f"{source}: missing energy arrays {sorted(missing)}")
        for name, arr in [*((f"energy_{k}", v) for k, v in self.energies.items()),
                          *((m, getattr(self, m)) for m in METRICS)]:
            if arr.shape != (b,):
                raise ValueError(f"{source}: array '{name}' has shape {arr.shape}, expected ({b},)")
        if not np.isfinite(self.pose).all():
            raise ValueError(f"{source}: 'pose' holds non-finite values")
        if self.flags is not None:
            for k, v in self.flags.items():
                if v.shape != (b,) or v.dtype != bool:
                    raise ValueError(f"{source}: flag '{k}' is not a ({b},) bool array")
            if "passed" not in self.flags:
                raise ValueError(f"{source}: flags lack 'passed'")


def write_prior_grasps(grasps: PriorGrasps, path: str | Path) -> None:
    """Write a :class:`PriorGrasps` as a Zarr v3 store, atomically."""
    grasps.validate(str(path))
    arrays: dict[str, tuple[np.ndarray, tuple[str, ...]]] = {
        "pose": (grasps.pose.astype(np.float32), ("grasp", "param")),
        "contact_idx": (grasps.contact_idx.astype(np.int32), ("grasp", "contact")),
        "plane": (grasps.plane.astype(np.float32), ("grasp", "plane")),
    }
    for k, v in grasps.energies.items():
        arrays[f"energy_{k}"] = (v.astype(np.float32), ("grasp",))
    for m in METRICS:
        arrays[m] = (getattr(grasps, m).astype(np.float64), ("grasp",))
    for k, v in (grasps.flags or {}).items():
        arrays[k if k == "passed" else f"pass_{k}"] = (v.astype(bool), ("grasp",))
    write_store(path, arrays, {**grasps.attrs, "object": grasps.object, "filtered": grasps.flags is not None},
                SCHEMA, SCHEMA_VERSION)


def read_prior_grasps(path: str | Path, filtered: bool | None = None) -> PriorGrasps:
    """Open and validate a prior-grasp store.

    Args:
        path: the store.
        filtered: require a filtered (True) or raw (False) store; None accepts either.

    Raises:
        ValueError: not a tohgs prior-grasp store, a wrong schema version, missing, damaged or inconsistent
            arrays (the message names the store and the problem).
    """
    arrays, attrs = read_store(path, SCHEMA, SCHEMA_VERSION, None, "prior-grasp store")
    if filtered is not None and bool(attrs.get("filtered")) != filtered:
        raise ValueError(f"{path}: expected a {'filtered' if filtered else 'raw'} store")

    def get(name: str) -> np.ndarray:
        if name not in arrays:
            raise ValueError(f"{path}: missing array '{name}'")
        return arrays[name]

    flags = None
    if attrs.get("filtered"):
        flags = {n[len("pass_"):]: get(n) for n in sorted(arrays) if n.startswith("pass_")}
        flags["passed"] = get("passed")
    grasps = PriorGrasps(
        object=str(attrs.get("object")), pose=get("pose").astype(np.float32), contact_idx=get("contact_idx"),
        plane=get("plane"), energies={k: get(f"energy_{k}") for k in ENERGY_TERMS}, pv=get("pv"), sd=get("sd"),
        contact_distance=get("contact_distance"), flags=flags,
        attrs={k: v for k, v in attrs.items() if k not in ("object", "filtered")})
    grasps.validate(str(path))
    return grasps
