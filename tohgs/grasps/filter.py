"""The prior-grasp quality filter: thresholds on the metrics, the joint limits and the optimiser energies.

It replaces the paper's manual removal of non-human-like grasps with the anatomical joint limits. A
grasp passes if every check passes:

- ``pv``: penetration volume below ``max_pv`` (4 cm^3 = 4e-6 m^3, the paper's "4e-6 cm^3" being a unit slip);
- ``sd``: simulation displacement below ``max_sd`` (3 cm);
- ``contact``: the hand within ``max_contact_distance`` (5 mm) of the object (GraspTTA's dataset filter);
- ``joints``: every finger parameter within the hand's anatomical limits (plus ``joint_tolerance``);
- ``energy``: the optimiser's final energies below bounds (the dataclass defaults are DexGraspNet's success
  thresholds, E_fc < 0.3, E_dis < 0.005 m, E_pen < 0.001 m; the default config loosens them, see
  config/README.md).

The energy and joint checks need no metric, so the synthesis can apply them first (:func:`screen_flags`) and
simulate SD only for the grasps that pass them: the others could not pass whatever their SD, and SD is most
of a grasp's measuring time. Their SD is NaN in the stores ("unsimulated"); the filter refuses thresholds
looser than the screen's, which could accept a grasp it never simulated.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.hand.layout import FINGER_POSE_DIM

log = logging.getLogger(__name__)

CHECKS = ("pv", "sd", "contact", "joints", "energy")
#: The thresholds of the checks that need no metric: the screen before SD (:func:`screen_flags`).
SCREEN_KEYS = ("max_fc", "max_dis", "max_pen", "joint_tolerance")


@dataclass(frozen=True)
class FilterThresholds:
    """Thresholds of the filter (SI units)."""

    max_pv: float = 4e-6
    max_sd: float = 0.03
    max_contact_distance: float = 0.005
    joint_tolerance: float = 0.0
    max_fc: float = 0.3
    max_dis: float = 0.005
    max_pen: float = 0.001


def quality_flags(pv: np.ndarray, sd: np.ndarray, contact_distance: np.ndarray, finger_pose: np.ndarray,
                  joint_limits: np.ndarray, e_fc: np.ndarray, e_dis: np.ndarray, e_pen: np.ndarray,
                  t: FilterThresholds) -> dict[str, np.ndarray]:
    """Pass flags of each check and overall.

    Args:
        pv: (B,) penetration volumes, m^3.
        sd: (B,) simulation displacements, m.
        contact_distance: (B,) smallest signed hand-object distance, m.
        finger_pose: (B, 45) finger parameters (the grasp vector's last 45 numbers), radians.
        joint_limits: (15, 3, 2) the hand's limits per joint and axis, radians.
        e_fc, e_dis, e_pen: (B,) the optimiser's final energies.
        t: the thresholds.

    Returns:
        ``{"pv", "sd", "contact", "joints", "energy", "passed"}``, each (B,) bool.
    """
    flags = {
        "pv": np.asarray(pv) < t.max_pv,
        "sd": np.asarray(sd) < t.max_sd,  # False where SD is NaN (not simulated)
        "contact": np.asarray(contact_distance) <= t.max_contact_distance,
        **_metric_free_flags(finger_pose, joint_limits, e_fc, e_dis, e_pen, t),
    }
    flags["passed"] = np.logical_and.reduce([flags[c] for c in CHECKS])
    return flags


def _metric_free_flags(finger_pose: np.ndarray, joint_limits: np.ndarray, e_fc: np.ndarray, e_dis: np.ndarray,
                       e_pen: np.ndarray, t: FilterThresholds) -> dict[str, np.ndarray]:
    """``{"joints", "energy"}`` flags, each (B,) bool (arguments as :func:`quality_flags`)."""
    lim = np.asarray(joint_limits).reshape(FINGER_POSE_DIM, 2)
    fp = np.asarray(finger_pose).reshape(-1, FINGER_POSE_DIM)
    return {
        "joints": np.all((fp >= lim[:, 0] - t.joint_tolerance) & (fp <= lim[:, 1] + t.joint_tolerance), axis=1),
        "energy": (np.asarray(e_fc) < t.max_fc) & (np.asarray(e_dis) < t.max_dis) & (np.asarray(e_pen) < t.max_pen),
    }


def screen_flags(finger_pose: np.ndarray, joint_limits: np.ndarray, e_fc: np.ndarray, e_dis: np.ndarray,
                 e_pen: np.ndarray, t: FilterThresholds) -> np.ndarray:
    """(B,) bool: the grasps that pass the checks needing no metric (energies and joint limits), the only
    ones the filter can accept whatever their PV, SD and contact (arguments as :func:`quality_flags`; only
    the thresholds in :data:`SCREEN_KEYS` are used)."""
    f = _metric_free_flags(finger_pose, joint_limits, e_fc, e_dis, e_pen, t)
    return f["joints"] & f["energy"]


def rejection_counts(flags: dict[str, np.ndarray], simulated: np.ndarray | None = None) -> dict[str, int]:
    """How many grasps fail each check (a grasp can fail several), and how many pass.

    With ``simulated`` ((B,) bool, the grasps whose SD was simulated), a grasp that was not is counted under
    ``"unsimulated"`` instead of ``"sd"`` (it failed the screen, :func:`screen_flags`).
    """
    sd_failed = ~flags["sd"] if simulated is None else ~flags["sd"] & np.asarray(simulated, dtype=bool)
    out = Counter({c: int((sd_failed if c == "sd" else ~flags[c]).sum()) for c in CHECKS})
    if simulated is not None:
        out["unsimulated"] = int((~np.asarray(simulated, dtype=bool)).sum())
    out["passed"] = int(flags["passed"].sum())
    return dict(out)


def check_screen(screen: dict[str, float] | None, t: FilterThresholds, source: str) -> None:
    """Refuse filter thresholds looser than the screen a raw store was measured under (``screen``: its
    :data:`SCREEN_KEYS` values, None when every grasp was simulated): a grasp they accept may never have
    been simulated. Raises ``ValueError`` naming ``source`` and the thresholds."""
    if screen is None:
        return
    looser = [f"{k} {getattr(t, k)} > {screen[k]}" for k in SCREEN_KEYS if getattr(t, k) > float(screen[k])]
    if looser:
        raise ValueError(f"{source}: SD was simulated only for grasps that pass the screen {screen}; the filter's "
                         f"{', '.join(looser)} could accept grasps never simulated: rerun the synthesis with "
                         "these thresholds (prior_grasps.simulate)")


def filter_prior_grasps(raw: str | Path, thresholds: dict[str, Any], out: str | Path):
    """Apply the filter to a raw store and write the filtered store (the same grasps plus pass flags).

    Args:
        raw: the raw store of :func:`tohgs.grasps.prior.make_prior_grasps`; its attribute ``joint_limits``
            holds the (15, 3, 2) anatomical limits (radians) of the hand that made the grasps, ``screen``
            the thresholds SD's screen used (None: every grasp simulated; see :func:`check_screen`).
        thresholds: a config mapping of :class:`FilterThresholds`.
        out: the filtered store.

    Returns:
        the filtered :class:`~tohgs.data.grasps.PriorGrasps`.
    """
    from tohgs.settings import settings_from
    from tohgs.data.grasps import read_prior_grasps, write_prior_grasps

    g = read_prior_grasps(raw, filtered=False)
    if "joint_limits" not in g.attrs:
        raise ValueError(f"{raw}: the raw store lacks the hand's 'joint_limits' attribute (written by an older "
                         "tohgs): rerun the synthesis")
    limits = np.asarray(g.attrs["joint_limits"], dtype=np.float64)
    if limits.shape != (15, 3, 2):
        raise ValueError(f"{raw}: attribute 'joint_limits' has shape {limits.shape}, expected (15, 3, 2)")
    t = settings_from(FilterThresholds, thresholds)
    check_screen(g.attrs.get("screen"), t, str(raw))
    flags = quality_flags(g.pv, g.sd, g.contact_distance, g.pose[:, 6:], limits, g.energies["fc"],
                          g.energies["dis"], g.energies["pen"], t)
    counts = rejection_counts(flags, np.isfinite(g.sd))
    log.info("%s: %d of %d grasps pass; rejected by check: %s", g.object, counts["passed"], len(g),
             {k: v for k, v in counts.items() if k != "passed"})
    g.flags = flags
    g.attrs = {**g.attrs, "thresholds": asdict(t), "rejections": counts}
    write_prior_grasps(g, out)
    return g


def summarize_prior_grasps(store_paths: list[str | Path], out_csv: str | Path, min_accepted: int = 16):
    """One row per object: grasps, accepted, failures per check (``fail_sd`` among the simulated grasps),
    ``unsimulated`` (screened out before SD) and timing; writes ``out_csv``.

    Logs the totals, the acceptance rate per check and the share of objects with at least
    ``min_accepted`` accepted grasps. Returns the table (a ``pandas.DataFrame``).
    """
    import pandas as pd

    from tohgs.data.grasps import read_prior_grasps
    from tohgs.io import atomic_path

    rows = []
    for p in store_paths:
        g = read_prior_grasps(p, filtered=True)
        timing = g.attrs.get("timing", {})
        counts = rejection_counts(g.flags, np.isfinite(g.sd))
        rows.append({"object": g.object, "grasps": len(g), "accepted": int(g.passed.sum()),
                     **{f"fail_{c}": counts[c] for c in CHECKS}, "unsimulated": counts["unsimulated"],
                     **{f"seconds_{k}": round(float(v), 2) for k, v in timing.items()}})
    df = pd.DataFrame(rows)
    with atomic_path(out_csv) as tmp:
        df.to_csv(tmp, index=False)
    if len(df):
        n = int(df.grasps.sum())
        log.info("%d objects, %d grasps, %d accepted (%.1f %%); objects with >= %d accepted: %d (%.0f %%)",
                 len(df), n, int(df.accepted.sum()), 100 * df.accepted.sum() / n, min_accepted,
                 int((df.accepted >= min_accepted).sum()), 100 * (df.accepted >= min_accepted).mean())
        for c in CHECKS:
            m = n - int(df.unsimulated.sum()) if c == "sd" else n
            log.info("check %-8s passes %.1f %% of the %d grasps it measured", c, 100 * (1 - df[f"fail_{c}"].sum() / max(m, 1)), m)
    return df
