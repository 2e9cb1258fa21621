"""The tables (the paper's Tables 1, 2, 4 and 5) from per-grasp metric rows (:mod:`tohgs.metrics.evaluate`),
and the QR grid.

A table is a config block (``tables.<name>``: its ``rows``, methods, and its ``columns``); every table has
one row per task and method, the methods in the block's order, labelled with their ``label``. Its columns
are ``task``, ``method`` and those the block lists, of these (:data:`METRIC_COLUMNS`):

=============  =================================================================================
column         meaning
=============  =================================================================================
task, method   the task and the method's display name (``dataset`` -> "Dataset", ...)
pv_avg/std     penetration volume, cm^3
sd_avg/std     simulation displacement, cm
cr             contact ratio, %: grasps with PV > 0
qr             quality ratio, %: grasps with PV < ``max_pv`` and SD < ``max_sd`` (3 cm^3, 2 cm)
ds             diversity: the mean over configurations of their DS, m (summed over hand vertices)
ds_per_vertex  DS divided by the hand's vertex count, cm: comparable across hands (x 7.78 for MANO's 778)
init_opp       hand vertices inside the initial scene, %
goal_opp       hand vertices inside the goal scene, %
ts             task success ``QR x (1 - InitOPP) x (1 - GoalOPP)`` from the averages
grasps         grasps evaluated; ``configs``: configurations they came from
missing        the task's test configurations (those of any row of the table) this row has none of
discarded      grasps the method discarded (a filter's, F-GraspTTA's): not evaluated, not in the others
sd_robust      robust SD, cm: the mean over the grasps with perturbed SDs of their median
sd_pass        %: the mean over those grasps of the fraction of perturbed SDs under ``max_sd``
sd_unstable    %: those grasps whose verdicts (SD < ``max_sd``: the protocol's and the perturbed) differ
sd_palm_avg    SD with gravity pulling the object out of the palm, cm (beyond the paper;
               ``evaluation.palm_sd``)
qr_palm        QR with that SD, %
=============  =================================================================================

With several seeds (``seeds``) every cell pools their grasps, and ``qr_seed_sd`` and ``ts_seed_sd`` give the
standard deviation across the seeds of QR and TS computed per seed.

The robust-SD columns (``evaluation.robust_sd``, :class:`tohgs.metrics.quality.RobustSDSettings`) are NaN
for a method evaluated without perturbations.

Every metric is of the kept grasps. A method that kept none has every metric 0 with its count of
discarded grasps, as the paper's F-GraspTTA Stacking row. A table may list ``pending`` rows, methods that
cannot be built yet, with the reason: they appear with empty cells (NaN) and the reason in the markdown.

With a bootstrap (:mod:`tohgs.metrics.bootstrap`), each metric column ``c`` but the counts gets its
interval as ``c_lo`` and ``c_hi`` in the frame (the CSV); the markdown writes ``value ± half-width``.
A table's ``paper`` list adds the paper's printed Table 1 value of those metrics as ``paper_<c>`` columns
(:mod:`tohgs.metrics.paper`), last.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from tohgs.metrics.bootstrap import (INTERVAL_COLUMNS, BootstrapSettings, config_ds, config_keys, config_stats,
                                     intervals, palm_sd, resample_weights, robust_stats)
from tohgs.metrics.paper import PAPER_METRICS, paper_value
from tohgs.metrics.quality_thresholds import QualityThresholds  # noqa: F401  (the tables' readers take it from here)

SEED_SPREAD_COLUMNS = ("qr", "ts")  # the columns whose spread across seeds the tables add
METRIC_COLUMNS = ("pv_avg", "pv_std", "sd_avg", "sd_std", "cr", "qr", "ds", "ds_per_vertex", "init_opp", "goal_opp",
                  "ts", "grasps", "configs", "missing", "discarded", "sd_robust", "sd_pass", "sd_unstable",
                  "sd_palm_avg", "qr_palm")
COUNT_COLUMNS = ("grasps", "configs", "missing", "discarded")
_HEADERS = {"task": "Task", "method": "Method", "pv_avg": "PV avg (cm³)", "pv_std": "PV std", "sd_avg": "SD avg (cm)",
            "sd_std": "SD std", "cr": "CR %", "qr": "QR %", "ds": "DS", "init_opp": "Init OPP %",
            "goal_opp": "Goal OPP %", "ts": "TS", "grasps": "grasps", "configs": "configs", "missing": "missing",
            "ds_per_vertex": "DS/vertex (cm)", "sd_palm_avg": "SD palm (cm)", "qr_palm": "QR palm %",
            "discarded": "discarded", "sd_robust": "robust SD (cm)", "sd_pass": "SD pass %",
            "sd_unstable": "SD unstable %", "qr_seed_sd": "QR sd (seeds)", "ts_seed_sd": "TS sd (seeds)"}


def _header(column: str) -> str:
    """A column's markdown header: the paper's value of a metric reads "<header> (paper)"."""
    if column.startswith("paper_") and column[6:] in PAPER_METRICS:
        return f"{_HEADERS.get(column[6:], column[6:])} (paper)"
    return _HEADERS.get(column, column)


def quality_ratio(frame: pd.DataFrame, t: QualityThresholds) -> float:
    """QR in % of the kept grasps (NaN without rows)."""
    if "kept" in frame.columns:
        frame = frame[frame.kept.astype(bool)]
    if len(frame) == 0:
        return float("nan")
    return float(t.passes(frame.pv, frame.sd).mean() * 100)


def summarize(frame: pd.DataFrame, t: QualityThresholds, task_configs: int | None = None) -> dict[str, float]:
    """Every metric column of one task and method's rows: of the kept grasps; NaN where there are no rows,
    0 where every grasp was discarded (module docstring). ``missing``: ``task_configs`` (the task's test
    configurations) less those the rows have (NaN without ``task_configs``)."""
    present = len(frame[["object", "config_index"]].drop_duplicates()) if len(frame) else 0
    missing = float("nan") if task_configs is None else float(task_configs - present)
    if "kept" in frame.columns:
        discarded = int((~frame.kept.astype(bool)).sum())
        frame = frame[frame.kept.astype(bool)]
    else:
        discarded = 0
    n = len(frame)
    if n == 0:
        out = {k: float("nan") if discarded == 0 or k.startswith("sd_") and k not in ("sd_avg", "sd_std") else 0.0
               for k in METRIC_COLUMNS}
        out.update(grasps=0, configs=0, discarded=discarded, missing=missing)
        return out
    qr = quality_ratio(frame, t)
    init_opp, goal_opp = float(frame.init_opp.mean()), float(frame.goal_opp.mean())
    ds = config_ds(frame)
    configs = len(frame[["object", "config_index"]].drop_duplicates())
    rob = robust_stats(frame, t.max_sd)
    sd_palm = palm_sd(frame)
    has_palm = sd_palm.notna()
    palm = ({"sd_palm_avg": float(sd_palm[has_palm].mean() * 100),
             "qr_palm": float(t.passes(frame.pv[has_palm], sd_palm[has_palm]).mean() * 100)}
            if has_palm.any() else dict.fromkeys(("sd_palm_avg", "qr_palm"), float("nan")))
    robust = ({"sd_robust": float(rob.sd_robust.mean() * 100), "sd_pass": float(rob.sd_pass.mean() * 100),
               "sd_unstable": float(rob.sd_unstable.mean() * 100)} if len(rob) else
              dict.fromkeys(("sd_robust", "sd_pass", "sd_unstable"), float("nan")))
    return {**robust, **palm, "pv_avg": float(frame.pv.mean() * 1e6), "pv_std": float(frame.pv.std(ddof=0) * 1e6),
            "sd_avg": float(frame.sd.mean() * 100), "sd_std": float(frame.sd.std(ddof=0) * 100),
            "cr": float((frame.pv > 0).mean() * 100), "qr": qr, "ds": float(ds.mean()),
            "ds_per_vertex": float(config_ds(frame, per_vertex=True).mean() * 100), "missing": missing,
            "init_opp": init_opp * 100, "goal_opp": goal_opp * 100,
            "ts": qr / 100 * (1 - init_opp) * (1 - goal_opp), "grasps": n, "configs": configs, "discarded": discarded}


def read_metrics(paths: list[str | Path], replicas: dict[str, dict[str, int]] | None = None) -> pd.DataFrame:
    """The rows of several metric files, concatenated (a missing column names the file).

    ``replicas`` (a method -> its seed replicas' names -> their seeds, :func:`tohgs.config.add_seed_replicas`):
    a replica's rows are renamed to its method's and get its seed in column ``seed`` (the tables pool them);
    rows of other methods get seed 0."""
    from tohgs.metrics.evaluate import COLUMNS, OPTIONAL_COLUMNS

    rename = {r: (m, seed) for m, reps in (replicas or {}).items() for r, seed in reps.items()}
    frames = []
    for p in paths:
        f = pd.read_parquet(p)
        missing = set(COLUMNS) - set(OPTIONAL_COLUMNS) - set(f.columns)
        if missing:
            raise ValueError(f"{p}: metric file lacks columns {sorted(missing)}")
        if len(f):
            method, seed = rename.get(str(f.method.iloc[0]), (str(f.method.iloc[0]), 0))
            f = f.assign(method=method, seed=seed)
        frames.append(f)
    return (pd.concat(frames, ignore_index=True) if frames else
            pd.DataFrame(columns=[*COLUMNS, "seed"]))


def seed_spread(frame: pd.DataFrame, t: QualityThresholds, columns: list[str]) -> dict[str, float]:
    """The standard deviation across seeds (ddof 1) of each of ``columns`` computed per seed
    (:func:`summarize`); NaN with fewer than two seeds."""
    seeds = sorted(frame.seed.unique()) if "seed" in frame.columns and len(frame) else []
    if len(seeds) < 2:
        return dict.fromkeys(columns, float("nan"))
    per = [summarize(frame[frame.seed == s], t) for s in seeds]
    return {c: float(np.std([p[c] for p in per], ddof=1)) for c in columns}


def metric_table(rows: pd.DataFrame, tasks: list[str], methods: list[str], labels: dict[str, str],
                 columns: list[str], t: QualityThresholds, pending: list[str] = (),
                 bootstrap: BootstrapSettings | None = None, paper: list[str] = ()) -> pd.DataFrame:
    """One row per task and method, in the given orders: ``task``, ``method`` (its label) and ``columns``;
    then per task a row of NaN for each label of ``pending`` (methods not available yet); last, for each
    of ``paper``, the paper's Table 1 value ``paper_<c>`` of the row's method (:mod:`tohgs.metrics.paper`;
    NaN for a method the paper does not have). With a
    ``bootstrap`` of samples > 0, the intervals ``<c>_lo``, ``<c>_hi`` of the columns that have them; the
    resamples are drawn once per task, over every configuration of the task's rows, and shared by its
    methods. Rows of several seeds (column ``seed``, :func:`read_metrics`) are pooled, and QR's and TS's
    standard deviation across the seeds is added as ``qr_seed_sd`` and ``ts_seed_sd``."""
    unknown = [c for c in columns if c not in METRIC_COLUMNS]
    if unknown:
        raise ValueError(f"unknown table columns {unknown} (known: {', '.join(METRIC_COLUMNS)})")
    ci = [c for c in columns if c in INTERVAL_COLUMNS] if bootstrap is not None and bootstrap.samples > 0 else []
    bounds = [f"{c}_{end}" for c in ci for end in ("lo", "hi")]
    several = "seed" in rows.columns and rows.seed.nunique() > 1
    spread = [c for c in columns if c in SEED_SPREAD_COLUMNS] if several else []
    bounds += [f"{c}_seed_sd" for c in spread]
    bounds += [f"paper_{c}" for c in paper]
    out = []
    for task in tasks:
        in_task = rows[rows.task == task]
        n_configs = len(config_keys(in_task[in_task.method.isin(methods)]))
        if ci:
            keys = config_keys(in_task)
            rng = np.random.default_rng([bootstrap.seed, tasks.index(task)])
            weights = resample_weights(keys.object.to_numpy(), bootstrap.samples, rng)
        for m in methods:
            sel = in_task[in_task.method == m]
            summary = summarize(sel, t, n_configs)
            row = {"task": task, "method": labels.get(m, m), **{c: summary[c] for c in columns}}
            if ci:
                iv = intervals(weights, config_stats(sel, keys, t.max_pv, t.max_sd), bootstrap.level)
                for c in ci:
                    row[f"{c}_lo"], row[f"{c}_hi"] = iv[c]
            if spread:
                row.update({f"{c}_seed_sd": v for c, v in seed_spread(sel, t, spread).items()})
            row.update({f"paper_{c}": paper_value(m, task, c) for c in paper})
            out.append(row)
        out += [{"task": task, "method": label, **dict.fromkeys([*columns, *bounds], float("nan"))} for label in pending]
    return pd.DataFrame(out, columns=["task", "method", *columns, *bounds])


def qr_grid(rows: pd.DataFrame, tasks: list[str], methods: list[str], labels: dict[str, str], max_pv: list[float],
            max_sd: list[float]) -> pd.DataFrame:
    """QR (%) for every PV x SD threshold pair (m^3, m; listed in cm^3 and cm), per task and method."""
    out = []
    for task in tasks:
        for m in methods:
            sel = rows[(rows.task == task) & (rows.method == m)]
            for pv in max_pv:
                for sd in max_sd:
                    out.append({"task": task, "method": labels.get(m, m), "max_pv_cm3": round(pv * 1e6, 6),
                                "max_sd_cm": round(sd * 100, 6), "qr": quality_ratio(sel, QualityThresholds(pv, sd))})
    return pd.DataFrame(out, columns=["task", "method", "max_pv_cm3", "max_sd_cm", "qr"])


def markdown(table: pd.DataFrame, digits: int = 3, notes: dict[str, str] | None = None) -> str:
    """A GitHub markdown table of :func:`metric_table`'s frame (NaN as an en dash; a column with an
    interval as ``value ± half-width``); ``notes`` (a method label -> a sentence) are marked on the label
    and listed below the table."""
    notes = notes or {}
    marks = {label: "*" * (k + 1) for k, label in enumerate(notes)}
    cols = [c for c in table.columns if not (c.endswith(("_lo", "_hi")) and c[:-3] in table.columns)]
    lines = ["| " + " | ".join(_header(c) for c in cols) + " |", "|" + "---|" * len(cols)]
    for _, r in table.iterrows():
        cells = []
        for c in cols:
            v = r[c]
            if c in COUNT_COLUMNS:
                cells.append(str(int(v)) if np.isfinite(v) else "–")
            elif isinstance(v, (float, np.floating)):
                fmt = f".{digits}f" if c in ("ts", "ds", "ts_seed_sd", "paper_ts") else ".2f"
                text = "–" if not np.isfinite(v) else format(v, fmt)
                if np.isfinite(v) and f"{c}_lo" in table.columns and np.isfinite(r[f"{c}_lo"]):
                    text += " ± " + format((r[f"{c}_hi"] - r[f"{c}_lo"]) / 2, fmt)
                cells.append(text)
            else:
                cells.append(str(v) + (marks.get(v, "") if c == "method" else ""))
        lines.append("| " + " | ".join(cells) + " |")
    lines += [""] + [f"{marks[label]} {label}: {why}" for label, why in notes.items()] if notes else []
    return "\n".join(lines) + "\n"
