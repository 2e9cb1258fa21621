"""The tables' confidence intervals: a hierarchical bootstrap over objects and their configurations."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tohgs.metrics.bootstrap import BootstrapSettings, cells, config_keys, config_stats, intervals, resample_weights
from tohgs.metrics.tables import METRIC_COLUMNS, QualityThresholds, markdown, metric_table, summarize

T = QualityThresholds()


def _rows(rng: np.random.Generator, objects: int = 20, configs: int = 6, grasps: int = 8, mean: float = 0.6,
          spread: float = 0.15, method: str = "m") -> pd.DataFrame:
    """Grasp rows whose quality is Bernoulli with a per-object and a per-configuration random effect about
    ``mean`` (so QR's expectation is ``mean`` x 100 and grasps of one object are correlated)."""
    p_obj = np.clip(mean + spread * rng.standard_normal(objects), 0.02, 0.98)
    p = np.clip(p_obj[:, None] + 0.05 * rng.standard_normal((objects, configs)), 0, 1)  # (O, C)
    good = (rng.random((objects, configs, grasps)) < p[..., None]).ravel()
    n = good.size
    o, c, g = np.meshgrid(np.arange(objects), np.arange(configs), np.arange(grasps), indexing="ij")
    ds = np.repeat(rng.uniform(0.05, 0.1, objects * configs), grasps)
    return pd.DataFrame({
        "task": "placing", "method": method, "object": np.char.add("o", o.ravel().astype(str)),
        "config_index": c.ravel(), "sample": g.ravel(), "pv": np.where(good, 1e-6, 5e-6) * rng.uniform(0.5, 1.0, n),
        "sd": np.where(good, 0.01, 0.05), "contact_distance": 0.0, "init_opp": rng.uniform(0, 0.02, n),
        "goal_opp": rng.uniform(0, 0.02, n), "ds": ds, "hand_vertices": 1609, "kept": True,
        # robust SD's perturbed SDs for the first two grasps of each configuration, none for the others
        "sd_perturbed": [list(rng.uniform(0.0, 0.04, 3)) if k < 2 else [] for k in g.ravel()],
        # SD out of the palm: about as good, NaN for every fourth grasp (a method evaluated without it)
        "sd_palm": np.where(g.ravel() % 4 == 3, np.nan, np.where(good, 0.012, 0.03) * rng.uniform(0.5, 1.5, n))})


def test_the_cells_of_unit_weights_are_the_tables_values():
    rows = _rows(np.random.default_rng(0), objects=4)
    rows.loc[rows.index[:5], "kept"] = False
    keys = config_keys(rows)
    values = cells(np.ones((1, len(keys))), config_stats(rows, keys, T.max_pv, T.max_sd))
    expect = summarize(rows, T)
    assert set(values) >= {"qr", "ts", "sd_robust", "sd_pass", "sd_unstable", "ds_per_vertex", "sd_palm_avg", "qr_palm"}
    for k, v in values.items():
        assert np.isfinite(v[0]) and v[0] == pytest.approx(expect[k], rel=1e-9, abs=1e-12), k


def test_the_interval_covers_a_known_mean_at_the_stated_rate():
    """95 % intervals of QR over 150 synthetic test sets of 20 objects: the true mean inside in 88-99 %."""
    rng = np.random.default_rng(1)
    hits = 0
    trials = 150
    for _ in range(trials):
        rows = _rows(rng, mean=0.6)
        keys = config_keys(rows)
        w = resample_weights(keys.object.to_numpy(), 300, rng)
        lo, hi = intervals(w, config_stats(rows, keys, T.max_pv, T.max_sd), 0.95)["qr"]
        hits += lo <= 60.0 <= hi
    assert 0.88 <= hits / trials <= 0.99, hits / trials


def test_resampling_draws_objects_then_their_configurations():
    objects = np.array(["a", "a", "a", "b", "c", "c"])
    w = resample_weights(objects, 500, np.random.default_rng(0))
    assert w.shape == (500, 6) and np.all(w.sum(1) > 0)
    # every resample draws 3 objects; an object drawn k times brings k x its size in configurations
    sizes = {"a": 3, "b": 1, "c": 2}
    for row in w[:50]:
        drawn = {o: row[objects == o].sum() / sizes[o] for o in sizes}
        assert sum(drawn.values()) == pytest.approx(3) and all(float(v).is_integer() for v in drawn.values())


def test_tables_carry_intervals_and_the_markdown_shows_them():
    rows = pd.concat([_rows(np.random.default_rng(2), objects=5, method="a"),
                      _rows(np.random.default_rng(3), objects=5, method="b", mean=0.3)], ignore_index=True)
    cols = ["qr", "ts", "grasps"]
    table = metric_table(rows, ["placing"], ["a", "b"], {"a": "A", "b": "B"}, cols, T,
                         bootstrap=BootstrapSettings(samples=200))
    assert list(table.columns) == ["task", "method", *cols, "qr_lo", "qr_hi", "ts_lo", "ts_hi"]
    for _, r in table.iterrows():
        assert r.qr_lo <= r.qr <= r.qr_hi and r.qr_hi - r.qr_lo > 1
    md = markdown(table)
    assert " ± " in md and "qr_lo" not in md
    plain = metric_table(rows, ["placing"], ["a"], {}, cols, T, bootstrap=BootstrapSettings(samples=0))
    assert list(plain.columns) == ["task", "method", *cols]
    with pytest.raises(ValueError):
        BootstrapSettings(level=1.5)
    assert set(cols) <= set(METRIC_COLUMNS)


def test_claims_hold_fail_or_cannot_tell_by_their_paired_interval():
    from tohgs.metrics.claims import claims_markdown, claims_table

    rows = pd.concat([_rows(np.random.default_rng(4), objects=6, method="good", mean=0.8),
                      _rows(np.random.default_rng(5), objects=6, method="bad", mean=0.3),
                      _rows(np.random.default_rng(6), objects=6, method="same", mean=0.8)], ignore_index=True)
    tables = {"t": {"rows": ["good", "bad", "same"]}}
    claims = {"a": {"table": "t", "better": "good", "than": ["bad"]},
              "b": {"table": "t", "better": "bad", "than": ["good"]},
              "c": {"table": "t", "better": "good", "than": ["same"]},
              "d": {"table": "t", "better": "good", "than": [], "exclude": ["same"], "metric": "init_opp"},
              "e": {"table": "t", "better": "good", "than": ["other"]}}
    out = claims_table(rows, claims, tables, {}, T, BootstrapSettings(samples=300), ["placing"]).set_index("claim")
    assert out.loc["a", "verdict"] == "holds" and out.loc["a", "lo"] > 0
    assert out.loc["b", "verdict"] == "does not hold" and out.loc["b", "difference"] < 0
    assert out.loc["c", "verdict"] == "cannot tell" and out.loc["c", "lo"] < 0 < out.loc["c", "hi"]
    # lower is better for OPP: the difference is the other's minus the method's (here about 0, same generator)
    assert out.loc["d", "than"] == "bad" and abs(out.loc["d", "difference"]) < 0.5
    assert out.loc["e", "verdict"].startswith("not checked: other")
    assert "| a: " in claims_markdown(out.reset_index(), 0.95)
    # objects needed to tell: a claim already told needs the objects it has; an undecided one more
    assert out.loc["a", "objects"] == 6 and out.loc["a", "objects_needed"] == 6
    assert not out.loc["c", "objects_needed"] <= 6
    # the per-object paired test against a slow reference: TS per object from the tables' summaries, then
    # every one of the 2^6 sign patterns; good against its twin is no better than chance
    import itertools

    d = np.array([summarize(rows[(rows.method == "good") & (rows.object == o)], T)["ts"]
                  - summarize(rows[(rows.method == "bad") & (rows.object == o)], T)["ts"] for o in sorted(rows.object.unique())])
    flips = np.array([abs(np.dot(sg, d)) / len(d) for sg in itertools.product((1, -1), repeat=len(d))])
    assert out.loc["a", "objects_favour"] == (d > 0).sum() >= 5
    assert out.loc["a", "p_objects"] == pytest.approx(np.mean(flips >= abs(d.mean()) - 1e-12))
    assert out.loc["b", "p_objects"] == out.loc["a", "p_objects"] and out.loc["b", "objects_favour"] == 6 - (d > 0).sum()
    told = out.loc["a", "p_objects"] < 0.05
    assert out.loc["a", "paired_verdict"] == ("holds" if told else "cannot tell")
    assert out.loc["b", "paired_verdict"] == ("does not hold" if told else "cannot tell")
    clear = pd.concat([_rows(np.random.default_rng(4), objects=10, method="good", mean=0.9, spread=0.03),
                       _rows(np.random.default_rng(5), objects=10, method="bad", mean=0.2, spread=0.03)])
    ten = claims_table(clear, {"a": claims["a"]}, tables, {}, T, BootstrapSettings(samples=100), ["placing"]).iloc[0]
    assert ten.objects_favour == 10 and ten.p_objects == pytest.approx(2 / 1024) and ten.paired_verdict == "holds"
    assert out.loc["c", "paired_verdict"] == "cannot tell" and out.loc["c", "p_objects"] > 0.05
    assert out.loc["e", "paired_verdict"].startswith("not checked")


def test_the_sign_flip_test_is_exact_for_few_objects_and_sampled_for_many():
    from tohgs.metrics.claims import sign_flip_test

    rng = np.random.default_rng(0)
    assert sign_flip_test(np.ones(3), rng) == pytest.approx(2 / 8)  # 3 objects can never tell at 5 %
    assert sign_flip_test(np.array([1.0, 1.0, 1.0, 1.0, 1.0, -1.0]), rng) == pytest.approx(14 / 64)
    assert np.isnan(sign_flip_test(np.array([np.nan]), rng))
    assert sign_flip_test(np.ones(30) + rng.normal(0, 0.1, 30), rng) < 1e-3  # 20000 random patterns
    # under the null (differences symmetric about 0) p is about uniform: 5 % of tests below 0.05
    ps = np.array([sign_flip_test(rng.normal(0, 1, 10), rng) for _ in range(400)])
    assert 0.02 < (ps < 0.05).mean() < 0.09 and 0.4 < np.median(ps) < 0.6


def test_objects_needed_follows_the_square_root_law():
    """A difference of d with a half-width h over K objects needs about K (h / d)^2 objects: the
    bootstrap's answer is within the grid's step of it (a factor 2 either way)."""
    from tohgs.metrics.claims import claims_table

    rows = pd.concat([_rows(np.random.default_rng(8), objects=8, method="a", mean=0.62, spread=0.2),
                      _rows(np.random.default_rng(9), objects=8, method="b", mean=0.55, spread=0.2)],
                     ignore_index=True)  # objects o0..o7 for both: a paired comparison
    out = claims_table(rows, {"x": {"table": "t", "better": "a", "than": ["b"]}}, {"t": {"rows": ["a", "b"]}}, {}, T,
                       BootstrapSettings(samples=400), ["placing"]).iloc[0]
    half, d = (out.hi - out.lo) / 2, abs(out.difference)
    expected = 8 * (half / d) ** 2
    assert out.verdict == "cannot tell" and expected > 8
    assert expected / 2.5 <= out.objects_needed <= expected * 2.5, (out.objects_needed, expected)
