"""The paper's claims as a table: for each claim and task, the measured difference of a metric between a
method and the best of the methods it is claimed to beat, its bootstrap interval, and a verdict.

A claim is a config block (``claims.<name>``): ``text`` (the claim in words), ``table`` (the table whose
rows it compares), ``better`` (a method), ``than`` (methods, or ``[]`` for every other row of the table
but those in ``exclude``), ``metric`` (a column with an interval, TS by default; for OPP, PV and SD
lower is better, and the difference is taken so that a positive value favours ``better``) and ``tasks``.

Per task, the difference ``d = m(better) - max_other m(other)`` (or ``min_other m(other) - m(better)``
where lower is better) is computed on the whole test set and on every hierarchical bootstrap resample
(:mod:`tohgs.metrics.bootstrap`; the same resamples for every method, so the comparison is paired). The
verdict: **holds** where the interval's lower end is above 0, **does not hold** where its upper end is
below 0, **cannot tell** otherwise.

Beside the bootstrap, a per-object paired test: for each test object, the difference of the metric between
``better`` and the other method that is best on the whole set, computed on that object's grasps alone;
``p_objects`` is the two-sided sign-flip permutation test of their mean (every one of the 2^K sign patterns
for up to :data:`EXACT_OBJECTS` objects, else :data:`FLIPS` random ones), ``objects_favour`` how many of the K
objects favour ``better``, and ``paired_verdict`` holds / does not hold where ``p_objects`` < 5 % (by the
sign of the mean) and cannot tell otherwise. With 5 or fewer objects the test can never reach 5 %.

``objects_needed``: how many test objects per task the benchmark would need for the interval to exclude 0,
were the difference what it is here, measured from the bootstrap: test sets of K' objects drawn (with
replacement, then their configurations) from the K of this run, for K' = K, 2K, 3K, 4K, 6K, 8K, ...
(:data:`SCALES`); the first K' whose interval of the difference excludes 0 (K where the verdict is told
already). NaN past the largest, or with no difference.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tohgs.metrics.bootstrap import (INTERVAL_COLUMNS, BootstrapSettings, cells, config_keys, config_stats,
                                     resample_weights)
from tohgs.metrics.tables import QualityThresholds

LOWER_IS_BETTER = ("pv_avg", "pv_std", "sd_avg", "sd_std", "init_opp", "goal_opp")
CLAIM_COLUMNS = ("claim", "text", "task", "metric", "better", "than", "difference", "lo", "hi", "verdict",
                 "objects", "objects_needed", "objects_favour", "p_objects", "paired_verdict")
EXACT_OBJECTS = 16  # up to this many objects the permutation test enumerates every sign pattern
FLIPS = 20000  # random sign patterns beyond
PAIRED_LEVEL = 0.05
SCALES = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64)  # test sets of K' = scale x K objects (objects_needed)


def objects_needed(keys: pd.DataFrame, difference, bootstrap: BootstrapSettings, seed: list[int],
                   scales=SCALES) -> float:
    """The smallest K' = scale x K test objects (K those of ``keys``) whose hierarchical bootstrap interval
    of ``difference(weights)`` (a function of (B, C) weights returning (B,) values) excludes 0; NaN if none
    of ``scales`` does (module docstring)."""
    objects = keys.object.to_numpy()
    k = len(np.unique(objects))
    tail = (1 - bootstrap.level) / 2 * 100
    samples = max(200, bootstrap.samples)
    for scale in scales:
        w = resample_weights(objects, samples, np.random.default_rng([*seed, scale]), draws=scale * k)
        d = difference(w)
        d = d[np.isfinite(d)]
        if len(d) == 0:
            return float("nan")
        if verdict(*np.percentile(d, [tail, 100 - tail])) != "cannot tell":
            return float(scale * k)
    return float("nan")


def sign_flip_test(differences: np.ndarray, rng: np.random.Generator) -> float:
    """Two-sided p-value of the mean of (K,) paired differences under random sign flips (a permutation
    test of "no difference": each object's difference is as likely negative as positive); NaN for K = 0.
    Exact (all 2^K patterns) for K <= :data:`EXACT_OBJECTS`, else :data:`FLIPS` random patterns."""
    d = np.asarray(differences, dtype=np.float64)
    d = d[np.isfinite(d)]
    k = len(d)
    if k == 0:
        return float("nan")
    if k <= EXACT_OBJECTS:
        signs = 1 - 2 * ((np.arange(2**k)[:, None] >> np.arange(k)[None, :]) & 1)  # (2^K, K)
    else:
        signs = rng.choice(np.array([-1, 1]), size=(FLIPS, k))
    means = np.abs(signs @ d) / k
    observed = abs(d.mean())
    return float(np.mean(means >= observed - 1e-12 * max(1.0, observed)))


def per_object_differences(keys: pd.DataFrame, stats: dict[str, np.ndarray], metric: str, better: str,
                           other: str, sign: float) -> np.ndarray:
    """(K,) per test object of ``keys`` (sorted by name): ``sign`` x (the metric of ``better`` - that of
    ``other``) on the object's configurations alone (:func:`tohgs.metrics.bootstrap.cells` with one weight
    row per object)."""
    objects = keys.object.to_numpy()
    names = np.unique(objects)
    w = (objects[None, :] == names[:, None]).astype(np.float64)  # (K, C)
    return sign * (cells(w, stats[better])[metric] - cells(w, stats[other])[metric])


def verdict(lo: float, hi: float) -> str:
    """``holds`` (lo > 0), ``does not hold`` (hi < 0) or ``cannot tell``."""
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return "cannot tell"
    return "holds" if lo > 0 else "does not hold" if hi < 0 else "cannot tell"


def needed(keys: pd.DataFrame, difference, told: str, bootstrap: BootstrapSettings, value: float,
           seed: list[int]) -> float:
    """``objects_needed`` of a claim's row: this run's objects where its verdict is told already, else the
    first larger test set of :func:`objects_needed` (NaN without intervals or a difference)."""
    if bootstrap.samples == 0 or not np.isfinite(value):
        return float("nan")
    if told in ("holds", "does not hold"):
        return float(keys.object.nunique())
    return objects_needed(keys, difference, bootstrap, seed, SCALES[1:])


def claim_rows(rows: pd.DataFrame, name: str, claim: dict, table_rows: list[str], labels: dict[str, str],
               t: QualityThresholds, bootstrap: BootstrapSettings, tasks: list[str]) -> list[dict]:
    """The rows of one claim (one per task of the claim that is among ``tasks``); where a compared
    method is not a row of the claim's table, the row says so instead of a verdict."""
    metric = claim.get("metric", "ts")
    if metric not in INTERVAL_COLUMNS:
        raise ValueError(f"claim {name!r}: metric {metric!r} has no interval (one of {', '.join(INTERVAL_COLUMNS)})")
    better = claim["better"]
    than = list(claim.get("than") or [m for m in table_rows if m != better and m not in claim.get("exclude", [])])
    missing = [m for m in [better, *than] if m not in table_rows]
    sign = -1.0 if metric in LOWER_IS_BETTER else 1.0
    out = []
    samples = max(1, bootstrap.samples)
    for task in [x for x in claim.get("tasks") or tasks if x in tasks]:
        if missing or not than:  # the table (a config changed its rows) cannot say
            why = f"not checked: {', '.join(missing) if missing else 'nothing to compare'} not in {claim['table']}"
            out.append({"claim": name, "text": claim.get("text", ""), "task": task, "metric": metric,
                        "better": labels.get(better, better), "than": ", ".join(labels.get(m, m) for m in than),
                        "difference": np.nan, "lo": np.nan, "hi": np.nan, "verdict": why, "objects": 0,
                        "objects_needed": np.nan, "objects_favour": 0, "p_objects": np.nan, "paired_verdict": why})
            continue
        in_task = rows[(rows.task == task) & rows.method.isin([better, *than])]
        keys = config_keys(in_task)
        weights = np.vstack([np.ones((1, len(keys))),
                             resample_weights(keys.object.to_numpy(), samples,
                                              np.random.default_rng([bootstrap.seed, tasks.index(task), 7]))])
        stats = {m: config_stats(in_task[in_task.method == m], keys, t.max_pv, t.max_sd) for m in [better, *than]}

        def difference(w: np.ndarray) -> np.ndarray:
            values = {m: sign * cells(w, stats[m])[metric] for m in stats}
            return values[better] - np.max(np.stack([values[m] for m in than]), 0)

        diff = difference(weights)  # (1 + B,): the whole set first
        tail = (1 - bootstrap.level) / 2 * 100
        boot = diff[1:][np.isfinite(diff[1:])]
        lo, hi = (np.percentile(boot, [tail, 100 - tail]) if len(boot) and bootstrap.samples > 0 else (np.nan, np.nan))
        told = verdict(lo, hi)
        whole = {m: sign * cells(weights[:1], stats[m])[metric][0] for m in than}
        best = max(than, key=lambda m: whole[m] if np.isfinite(whole[m]) else -np.inf)
        per_object = per_object_differences(keys, stats, metric, better, best, sign)
        p = sign_flip_test(per_object, np.random.default_rng([bootstrap.seed, tasks.index(task), 13]))
        mean = float(np.nanmean(per_object)) if np.isfinite(per_object).any() else float("nan")
        paired = (("holds" if mean > 0 else "does not hold") if np.isfinite(p) and p < PAIRED_LEVEL
                  else "cannot tell")
        out.append({"claim": name, "text": claim.get("text", ""), "task": task, "metric": metric,
                    "better": labels.get(better, better), "than": ", ".join(labels.get(m, m) for m in than),
                    "difference": float(diff[0]), "lo": float(lo), "hi": float(hi), "verdict": told,
                    "objects": int(keys.object.nunique()),
                    "objects_needed": needed(keys, difference, told, bootstrap, diff[0],
                                             [bootstrap.seed, tasks.index(task), 11]),
                    "objects_favour": int((per_object > 0).sum()), "p_objects": p, "paired_verdict": paired})
    return out


def claims_table(rows: pd.DataFrame, claims: dict[str, dict], tables: dict[str, dict], labels: dict[str, str],
                 t: QualityThresholds, bootstrap: BootstrapSettings, tasks: list[str]) -> pd.DataFrame:
    """Every claim's rows (module docstring); ``tables``: each table's config block (its ``rows``)."""
    out = []
    for name, claim in claims.items():
        if claim["table"] not in tables:
            raise ValueError(f"claim {name!r}: no table {claim['table']!r} (tables: {', '.join(tables)})")
        out += claim_rows(rows, name, claim, list(tables[claim["table"]]["rows"]), labels, t, bootstrap, tasks)
    return pd.DataFrame(out, columns=list(CLAIM_COLUMNS))


def claims_markdown(table: pd.DataFrame, level: float) -> str:
    """The claims table in markdown: per claim and task, the difference with its interval and the verdict."""
    lines = [f"| Claim | Task | Metric | Method | Against (best of) | Difference | {level:.0%} interval | Verdict | "
             "Test objects: here / to tell | Objects favouring | Paired p | Paired verdict |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for _, r in table.iterrows():
        interval = "–" if not np.isfinite(r.lo) else f"[{r.lo:+.3f}, {r.hi:+.3f}]"
        diff = "–" if not np.isfinite(r.difference) else f"{r.difference:+.3f}"
        need = (f"{int(r.objects_needed)}" if np.isfinite(r.objects_needed) else
                f"> {SCALES[-1] * int(r.objects)}" if np.isfinite(r.difference) else "–")
        p = "–" if not np.isfinite(r.p_objects) else f"{r.p_objects:.3f}"
        lines.append(f"| {r.claim}: {r.text} | {r.task} | {r.metric} | {r.better} | {r.than} | {diff} | "
                     f"{interval} | {r.verdict} | {int(r.objects)} / {need} | {int(r.objects_favour)} / "
                     f"{int(r.objects)} | {p} | {r.paired_verdict} |")
    lines += ["", "Difference: the method's value minus the best of the others' (for OPP, PV and SD the others' "
              "minus the method's), so a positive value favours the method; intervals from the hierarchical "
              "bootstrap over test objects and configurations, paired across methods. Test objects to tell: "
              "the fewest test objects per task (drawn like this run's) whose interval would exclude 0 at "
              "this difference, from the bootstrap. Paired: per test object, the method against the other that is "
              "best on the whole set; the p-value of a sign-flip permutation test over the objects (it cannot go "
              "below 5 % with 5 or fewer objects)."]
    return "\n".join(lines) + "\n"
