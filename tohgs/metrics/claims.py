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
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tohgs.metrics.bootstrap import (INTERVAL_COLUMNS, BootstrapSettings, cells, config_keys, config_stats,
                                     resample_weights)
from tohgs.metrics.tables import QualityThresholds

LOWER_IS_BETTER = ("pv_avg", "pv_std", "sd_avg", "sd_std", "init_opp", "goal_opp")
CLAIM_COLUMNS = ("claim", "text", "task", "metric", "better", "than", "difference", "lo", "hi", "verdict")


def verdict(lo: float, hi: float) -> str:
    """``holds`` (lo > 0), ``does not hold`` (hi < 0) or ``cannot tell``."""
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return "cannot tell"
    return "holds" if lo > 0 else "does not hold" if hi < 0 else "cannot tell"


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
                        "difference": np.nan, "lo": np.nan, "hi": np.nan, "verdict": why})
            continue
        in_task = rows[(rows.task == task) & rows.method.isin([better, *than])]
        keys = config_keys(in_task)
        weights = np.vstack([np.ones((1, len(keys))),
                             resample_weights(keys.object.to_numpy(), samples,
                                              np.random.default_rng([bootstrap.seed, tasks.index(task), 7]))])
        values = {m: sign * cells(weights, config_stats(in_task[in_task.method == m], keys, t.max_pv, t.max_sd))[metric]
                  for m in [better, *than]}
        diff = values[better] - np.max(np.stack([values[m] for m in than]), 0)  # (1 + B,): the whole set first
        tail = (1 - bootstrap.level) / 2 * 100
        boot = diff[1:][np.isfinite(diff[1:])]
        lo, hi = (np.percentile(boot, [tail, 100 - tail]) if len(boot) and bootstrap.samples > 0 else (np.nan, np.nan))
        out.append({"claim": name, "text": claim.get("text", ""), "task": task, "metric": metric,
                    "better": labels.get(better, better), "than": ", ".join(labels.get(m, m) for m in than),
                    "difference": float(diff[0]), "lo": float(lo), "hi": float(hi), "verdict": verdict(lo, hi)})
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
    lines = [f"| Claim | Task | Metric | Method | Against (best of) | Difference | {level:.0%} interval | Verdict |",
             "|---|---|---|---|---|---|---|---|"]
    for _, r in table.iterrows():
        interval = "–" if not np.isfinite(r.lo) else f"[{r.lo:+.3f}, {r.hi:+.3f}]"
        diff = "–" if not np.isfinite(r.difference) else f"{r.difference:+.3f}"
        lines.append(f"| {r.claim}: {r.text} | {r.task} | {r.metric} | {r.better} | {r.than} | {diff} | "
                     f"{interval} | {r.verdict} |")
    lines += ["", "Difference: the method's value minus the best of the others' (for OPP, PV and SD the others' "
              "minus the method's), so a positive value favours the method; intervals from the hierarchical "
              "bootstrap over test objects and configurations, paired across methods."]
    return "\n".join(lines) + "\n"
