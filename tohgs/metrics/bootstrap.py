"""Confidence intervals of the tables' cells: a hierarchical bootstrap over the test set.

A table cell (QR, OPP, TS, PV, SD, ...) is a function of the grasps of one task and method. The test set
is a few objects with a few configurations each, and grasps of one configuration are not independent, so
the resampling follows the data's structure: objects with replacement, then, within each drawn object,
its configurations with replacement (every grasp of a drawn configuration comes along). Each resample
is a vector of configuration weights (how often each was drawn); every cell is a ratio of weighted sums
of per-configuration statistics (:func:`config_stats`), so ``B`` resamples are one (B, C) @ (C, k)
product, not B recomputations. One set of weights, over the task's configurations, serves every method
of the task, so differences between methods (paired: the same configurations) have intervals too.

The interval is the percentile interval of the resampled values at ``level``; the point is the value
on the whole test set (what :func:`tohgs.metrics.tables.summarize` gives).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tohgs.metrics.quality_thresholds import QualityThresholds

#: The cells that get intervals (the counts ``grasps``, ``configs`` and ``discarded`` do not).
INTERVAL_COLUMNS = ("pv_avg", "pv_std", "sd_avg", "sd_std", "cr", "qr", "ds", "ds_per_vertex", "init_opp", "goal_opp",
                    "ts", "sd_robust", "sd_pass", "sd_unstable", "sd_palm_avg", "qr_palm")
_STATS = ("n", "pv", "pv2", "sd", "sd2", "contact", "quality", "init_opp", "goal_opp", "ds", "has_ds",
          "n_robust", "sd_robust", "sd_pass", "sd_unstable", "ds_vertex", "n_palm", "sd_palm", "quality_palm")


def robust_stats(frame: pd.DataFrame, max_sd: float) -> pd.DataFrame:
    """Per grasp of ``frame`` with perturbed SDs (column ``sd_perturbed``, lists in m; the others are
    dropped): ``sd_robust`` their median (m), ``sd_pass`` the fraction under ``max_sd``, ``sd_unstable`` 1
    where the verdicts (SD < max_sd) of the protocol's SD and the perturbed ones are not all the same."""
    cols = ["object", "config_index", "sd_robust", "sd_pass", "sd_unstable"]
    if "sd_perturbed" not in frame.columns or len(frame) == 0:
        return pd.DataFrame(columns=cols)
    has = frame.sd_perturbed.map(lambda v: isinstance(v, (list, tuple, np.ndarray)) and len(v) > 0).to_numpy(bool)
    f = frame[has]
    if len(f) == 0:
        return pd.DataFrame(columns=cols)
    values = [np.asarray(v, dtype=np.float64) for v in f.sd_perturbed]
    passes = [float((v < max_sd).mean()) for v in values]
    unstable = [float(len({bool(x < max_sd) for x in v} | {bool(sd < max_sd)}) > 1) for v, sd in zip(values, f.sd)]
    return pd.DataFrame({"object": f.object.to_numpy(), "config_index": f.config_index.to_numpy(),
                         "sd_robust": [float(np.median(v)) for v in values], "sd_pass": passes,
                         "sd_unstable": unstable})


@dataclass(frozen=True)
class BootstrapSettings:
    """``samples`` resamples (0: no intervals), the interval's ``level`` and the resampling ``seed``."""

    samples: int = 1000
    level: float = 0.95
    seed: int = 0

    def __post_init__(self):
        if self.samples < 0 or not 0 < self.level < 1:
            raise ValueError(f"bootstrap needs samples >= 0 and 0 < level < 1, got {self.samples}, {self.level}")


def config_keys(frame: pd.DataFrame) -> pd.DataFrame:
    """The task's configurations, (object, config_index), sorted: the columns of the weights."""
    return frame[["object", "config_index"]].drop_duplicates().sort_values(["object", "config_index"]).reset_index(drop=True)


def config_ds(frame: pd.DataFrame, per_vertex: bool = False) -> pd.Series:
    """DS per configuration (object, config_index) and, for rows of several seeds (column ``seed``,
    :func:`tohgs.metrics.tables.read_metrics`), per seed: each (configuration, seed)'s first row's; with
    ``per_vertex`` divided by the hand's vertex count (column ``hand_vertices``), m per vertex."""
    keys = ["object", "config_index"] + (["seed"] if "seed" in frame.columns else [])
    if per_vertex:
        return frame.assign(ds=frame.ds / frame.hand_vertices).groupby(keys).ds.first()
    return frame.groupby(keys).ds.first()


def palm_sd(frame: pd.DataFrame) -> pd.Series:
    """The rows' SD out of the palm (column ``sd_palm``, m; NaN for rows without one, and for files that
    predate it)."""
    return frame.sd_palm if "sd_palm" in frame.columns else pd.Series(np.nan, index=frame.index)


def config_stats(frame: pd.DataFrame, keys: pd.DataFrame, max_pv: float, max_sd: float) -> np.ndarray:
    """(C, 19) per configuration of ``keys``: kept grasps n, the sums of PV, PV^2, SD, SD^2 (SI units), the
    counts in contact (PV > 0) and of quality (PV < max_pv and SD < max_sd), the sums of the two OPPs
    (fractions), the sum of the configuration's DS over its seeds and how many seeds have one; then the
    count of grasps with perturbed SDs and the sums of their :func:`robust_stats`; then the sum of DS per
    hand vertex, and the count of grasps with an SD out of the palm, its sum and its quality count."""
    if "kept" in frame.columns:
        frame = frame[frame.kept.astype(bool)]
    out = np.zeros((len(keys), len(_STATS)))
    if len(frame) == 0:
        return out
    sd_palm = palm_sd(frame)
    t = QualityThresholds(max_pv, max_sd)
    f = frame.assign(pv2=frame.pv**2, sd2=frame.sd**2, contact=(frame.pv > 0).astype(float),
                     quality=t.passes(frame.pv, frame.sd).astype(float),
                     has_palm=sd_palm.notna().astype(float), sd_palm=sd_palm.fillna(0.0),
                     quality_palm=t.passes(frame.pv, sd_palm).astype(float))
    g = f.groupby(["object", "config_index"])
    ds_g = config_ds(f).groupby(level=["object", "config_index"])
    agg = pd.DataFrame({"n": g.size(), "pv": g.pv.sum(), "pv2": g.pv2.sum(), "sd": g.sd.sum(), "sd2": g.sd2.sum(),
                        "contact": g.contact.sum(), "quality": g.quality.sum(), "init_opp": g.init_opp.sum(),
                        "goal_opp": g.goal_opp.sum(), "ds": ds_g.sum(), "has_ds": ds_g.count().astype(float),
                        "ds_vertex": config_ds(f, per_vertex=True).groupby(level=["object", "config_index"]).sum(),
                        "n_palm": g.has_palm.sum(), "sd_palm": g.sd_palm.sum(), "quality_palm": g.quality_palm.sum()})
    rob = robust_stats(frame, max_sd)
    if len(rob):
        gr = rob.groupby(["object", "config_index"])
        agg = agg.join(pd.DataFrame({"n_robust": gr.size(), "sd_robust": gr.sd_robust.sum(),
                                     "sd_pass": gr.sd_pass.sum(), "sd_unstable": gr.sd_unstable.sum()}))
    idx = pd.MultiIndex.from_frame(keys)
    return agg.reindex(idx).reindex(columns=list(_STATS)).fillna(0.0).to_numpy(dtype=np.float64)


def cells(weights: np.ndarray, stats: np.ndarray) -> dict[str, np.ndarray]:
    """Every interval column (units as the tables': cm^3, cm, %; DS per vertex in cm) for (B, C)
    configuration weights and (C, 19) :func:`config_stats`; (B,) each, NaN where a resample holds no kept
    grasp (no perturbed one for the robust-SD columns, no SD out of the palm for those columns)."""
    s = weights @ stats  # (B, 19)
    col = {k: s[:, i] for i, k in enumerate(_STATS)}
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(col["n"] > 0, col["n"], np.nan)
        nr = np.where(col["n_robust"] > 0, col["n_robust"], np.nan)
        npalm = np.where(col["n_palm"] > 0, col["n_palm"], np.nan)
        has_ds = np.where(col["has_ds"] > 0, col["has_ds"], np.nan)
        pv, sd = col["pv"] / n, col["sd"] / n
        qr = col["quality"] / n
        init, goal = col["init_opp"] / n, col["goal_opp"] / n
        return {"pv_avg": pv * 1e6, "pv_std": np.sqrt(np.maximum(col["pv2"] / n - pv**2, 0)) * 1e6,
                "sd_avg": sd * 100, "sd_std": np.sqrt(np.maximum(col["sd2"] / n - sd**2, 0)) * 100,
                "cr": col["contact"] / n * 100, "qr": qr * 100,
                "ds": col["ds"] / has_ds, "ds_per_vertex": col["ds_vertex"] / has_ds * 100,
                "init_opp": init * 100, "goal_opp": goal * 100, "ts": qr * (1 - init) * (1 - goal),
                "sd_robust": col["sd_robust"] / nr * 100, "sd_pass": col["sd_pass"] / nr * 100,
                "sd_unstable": col["sd_unstable"] / nr * 100, "sd_palm_avg": col["sd_palm"] / npalm * 100,
                "qr_palm": col["quality_palm"] / npalm * 100}


def resample_weights(objects: np.ndarray, samples: int, rng: np.random.Generator,
                     draws: int | None = None) -> np.ndarray:
    """(samples, C) hierarchical bootstrap weights for C configurations of the given (C,) objects: draw as
    many objects as there are (or ``draws``: a test set of that many objects like these), with
    replacement; within each drawn object, as many of its configurations as it has, with replacement; a
    configuration's weight is how often it was drawn."""
    objects = np.asarray(objects)
    c = len(objects)
    _, members = np.unique(objects, return_inverse=True)
    order = np.argsort(members, kind="stable")  # the configurations grouped by object
    sizes = np.bincount(members)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    k = len(sizes)
    drawn = rng.integers(0, k, (samples, k if draws is None else int(draws)))  # (B, K) the objects drawn
    slot = np.arange(sizes.max())  # (M,) the draws within an object, the first sizes[obj] of them real
    u = rng.random((*drawn.shape, len(slot)))
    pick = starts[drawn][..., None] + np.floor(u * sizes[drawn][..., None]).astype(np.int64)  # (B, K, M)
    real = slot[None, None, :] < sizes[drawn][..., None]
    flat = (np.arange(samples)[:, None, None] * c + order[pick])[real]
    return np.bincount(flat, minlength=samples * c).reshape(samples, c).astype(np.float64)


def intervals(weights: np.ndarray, stats: np.ndarray, level: float) -> dict[str, tuple[float, float]]:
    """The percentile interval ``(lo, hi)`` at ``level`` of every interval column over the resamples."""
    tail = (1 - level) / 2 * 100
    out = {}
    for k, v in cells(weights, stats).items():
        v = v[np.isfinite(v)]
        out[k] = (float(np.percentile(v, tail)), float(np.percentile(v, 100 - tail))) if len(v) else (np.nan, np.nan)
    return out
