"""What the contact maps a row's hands were made from say about those hands' PV and SD: per grasp, three
statistics of its map, and two rows of one task (a generator fed sampled maps and the same generator fed
ground-truth maps) compared by least squares with and without them: whether what the rows' maps differ
in accounts for how their hands differ (why ground-truth maps need not give a generator better grasps).

The statistics of a map ``c`` (N,) in [0, 1] on the object's (N, 3) points in the network frame (the object's
initial centroid at the origin):

- ``mean_c2``: the mean of c^2 (how much of the object the map covers, and how strongly);
- ``share_above_09``: the share of points above 0.9 (a hand within about 1 mm at the contact alpha of 100);
- ``offset_cm``: the distance, cm, of the map's contact-weighted centroid from the object's centroid (where
  on the object the contact lies; a grasp far from the centre of mass holds a heavy end).

The comparison regresses an outcome (``pv``, cm^3, or ``sd``, cm) on ``1 + row`` (``row`` 1 for the second
row's grasps) and on ``1 + row + the standardised statistics``: the first ``row`` coefficient is the rows'
difference, the second what is left of it once the maps' statistics are accounted for (near 0: the
statistics carry the difference). Intervals: the hierarchical bootstrap of the tables
(:func:`tohgs.metrics.bootstrap.resample_weights`: objects, then their configurations), as weighted least
squares with each grasp weighted by how often its configuration was drawn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from tohgs.metrics.bootstrap import BootstrapSettings, resample_weights

#: The per-grasp statistics of a map (module docstring), in the order of the regression's columns.
STATISTICS = ("mean_c2", "share_above_09", "offset_cm")


def map_statistics(contact: np.ndarray, points: np.ndarray) -> dict[str, np.ndarray]:
    """The statistics (module docstring) of (S, N) contact maps on one configuration's (N, 3) points (m,
    network frame): each (S,). A map that is 0 everywhere has offset 0."""
    c = np.asarray(contact, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    if c.ndim != 2 or p.shape != (c.shape[1], 3):
        raise ValueError(f"map_statistics needs (S, N) maps and (N, 3) points, got {c.shape} and {p.shape}")
    total = c.sum(-1, keepdims=True)
    centroid = (c @ p) / np.where(total > 0, total, 1.0)
    return {"mean_c2": (c ** 2).mean(-1), "share_above_09": (c > 0.9).mean(-1),
            "offset_cm": np.linalg.norm(centroid, axis=-1) * 100.0}


def configuration_points(shard_paths: list[str | Path]) -> dict[tuple[str, int], np.ndarray]:
    """The (N, 3) object points of every configuration of the task's map shards, by (object, config_index)."""
    from tohgs.data.maps import read_map_shard

    out = {}
    for path in shard_paths:
        shard = read_map_shard(path)
        objects = list(shard.attrs["objects"])
        for c in range(shard.n_configs):
            out[(objects[int(shard.object_id[c])], int(shard.config_index[c]))] = shard.points[c]
    return out


def grasp_table(prediction_store: str | Path, metrics_file: str | Path,
                points: dict[tuple[str, int], np.ndarray]) -> pd.DataFrame:
    """One row per predicted grasp of one task and method: ``object``, ``config_index``, ``sample``, the
    :data:`STATISTICS` of the map it was made from, its ``pv`` (cm^3) and ``sd`` (cm) from the evaluation's
    metrics file; ``points`` from :func:`configuration_points`.

    Raises:
        ValueError: a configuration of the predictions that ``points`` or the metrics lack (named).
    """
    from tohgs.data.predictions import read_predictions

    arrays, attrs = read_predictions(prediction_store)
    objects = list(attrs["objects"])
    metrics = pd.read_parquet(metrics_file).set_index(["object", "config_index", "sample"]).sort_index()
    frames = []
    for c in range(len(arrays["object_id"])):
        key = (objects[int(arrays["object_id"][c])], int(arrays["config_index"][c]))
        if key not in points:
            raise ValueError(f"{prediction_store}: configuration {key} has no points in the map shards given")
        stats = map_statistics(arrays["contact"][c], points[key])
        n = arrays["contact"].shape[1]
        idx = pd.MultiIndex.from_arrays([[key[0]] * n, [key[1]] * n, np.arange(n)])
        missing = idx.difference(metrics.index)
        if len(missing):
            raise ValueError(f"{metrics_file}: no metrics for {list(missing)[:3]} of {prediction_store}")
        m = metrics.loc[idx]
        frames.append(pd.DataFrame({"object": key[0], "config_index": key[1], "sample": np.arange(n), **stats,
                                    "pv": m["pv"].to_numpy() * 1e6, "sd": m["sd"].to_numpy() * 100.0}))
    return pd.concat(frames, ignore_index=True)


def _wls(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The weighted least-squares coefficients of (G,) ``y`` on (G, k) ``x`` with (G,) weights ``w``."""
    sw = np.sqrt(w)[:, None]
    return np.linalg.lstsq(x * sw, y * sw[:, 0], rcond=None)[0]


def compare_rows(first: pd.DataFrame, second: pd.DataFrame, outcome: str,
                 boot: BootstrapSettings = BootstrapSettings(samples=300)) -> dict[str, dict[str, float]]:
    """The ``outcome`` column of two rows' :func:`grasp_table` regressed on the row and on the row and the
    maps' statistics (module docstring), with intervals.

    Returns:
        ``{"means": {row: {column: mean}}, "row_alone": ..., "row_given_maps": ..., "<statistic>": ...}``,
        each coefficient a dict of ``value``, ``lo``, ``hi`` (the statistics' per standard deviation of the
        two rows' grasps together, in the outcome's unit; ``row_*`` the second row minus the first).
    """
    both = pd.concat([first.assign(row=0.0), second.assign(row=1.0)], ignore_index=True)
    z = [(both[s] - both[s].mean()) / (both[s].std() if both[s].std() > 0 else 1.0) for s in STATISTICS]
    ones = np.ones(len(both))
    x_alone = np.column_stack([ones, both["row"]])
    x_maps = np.column_stack([ones, both["row"], *z])
    y = both[outcome].to_numpy(dtype=np.float64)
    point = np.r_[_wls(x_alone, y, ones)[1], _wls(x_maps, y, ones)[1:]]
    keys = pd.MultiIndex.from_frame(both[["object", "config_index"]])
    configs = keys.unique()
    where = configs.get_indexer(keys)  # each grasp's configuration
    names = ["row_alone", "row_given_maps", *STATISTICS]
    out: dict = {"means": {"first": first[[*STATISTICS, "pv", "sd"]].mean().to_dict(),
                           "second": second[[*STATISTICS, "pv", "sd"]].mean().to_dict()}}
    if boot.samples:
        weights = resample_weights(np.asarray(configs.get_level_values(0)), boot.samples,
                                   np.random.default_rng(boot.seed))[:, where]  # (B, G)
        draws = np.array([np.r_[_wls(x_alone, y, w)[1], _wls(x_maps, y, w)[1:]] for w in weights])
        tail = (1 - boot.level) / 2 * 100
        lo, hi = np.percentile(draws, tail, axis=0), np.percentile(draws, 100 - tail, axis=0)
    else:
        lo = hi = np.full(len(names), np.nan)
    for k, name in enumerate(names):
        out[name] = {"value": float(point[k]), "lo": float(lo[k]), "hi": float(hi[k])}
    return out
