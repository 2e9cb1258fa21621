"""The paper's Table 1 (Liu, Chao, Chen, ICCV 2025), as printed, for the tables' ``paper_<metric>`` columns.

These are the published numbers (the paper's `tohgs-iccv2025.tex`, Table 1: 21 unseen objects and 6 unseen
bricks, 10 configurations each, 16 grasps, MANO's 778 vertices), placed next to this run's so that a reader
compares the two without a second document. They are reference values, never used as results: a row whose
method the paper does not have (the Dataset row, Ours with ground-truth contact, a user's method) gets
empty cells.

Units are the tables': PV in cm^3, SD in cm, CR, QR and OPP in %, DS summed over MANO's 778 vertices (m),
``ds_per_vertex`` that DS over 778 in cm, TS a ratio. The paper prints FLEX's Stacking CR as "0/0"; it is 0.
"""

from __future__ import annotations

MANO_VERTICES = 778

#: The paper's Table 1 columns, in its order.
PAPER_COLUMNS = ("pv_avg", "pv_std", "sd_avg", "sd_std", "cr", "qr", "ds", "init_opp", "goal_opp", "ts")

_ROWS: dict[str, dict[str, tuple[float, ...]]] = {
    # method (this project's config name): task -> the ten PAPER_COLUMNS
    "grasptta": {"placing": (1.83, 2.51, 2.55, 2.90, 98.92, 59.10, 75.01, 21.36, 17.67, 0.382),
                 "stacking": (4.31, 2.77, 0.28, 0.31, 100.00, 34.87, 0.30, 26.05, 8.32, 0.236),
                 "shelving": (1.84, 2.34, 2.54, 2.91, 99.04, 58.86, 74.63, 15.70, 13.61, 0.428)},
    "f-grasptta": {"placing": (1.85, 2.29, 2.47, 2.85, 99.78, 58.46, 75.55, 0.54, 15.41, 0.491),
                   "stacking": (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                   "shelving": (1.88, 2.08, 2.68, 3.12, 99.50, 58.08, 74.84, 1.00, 11.09, 0.511)},
    "contactgen": {"placing": (1.44, 1.99, 3.85, 6.75, 93.57, 47.29, 87.01, 5.92, 17.67, 0.366),
                   "stacking": (0.66, 0.66, 1.85, 2.94, 94.89, 78.35, 62.53, 7.80, 9.44, 0.638),
                   "shelving": (1.43, 2.12, 3.90, 4.03, 93.13, 46.32, 89.79, 6.42, 13.17, 0.376)},
    "scenediffuser": {"placing": (1.39, 2.04, 3.10, 3.49, 96.51, 54.58, 67.79, 20.88, 16.17, 0.362),
                      "stacking": (0.53, 0.81, 1.62, 2.53, 94.85, 78.35, 63.13, 25.45, 9.66, 0.527),
                      "shelving": (1.37, 2.20, 3.35, 3.68, 95.91, 50.86, 68.18, 14.60, 13.77, 0.376)},
    "flex": {"placing": (2.61, 2.86, 1.62, 2.31, 99.88, 58.09, 32.92, 6.84, 5.55, 0.511),
             "stacking": (0.0, 0.0, 10.65, 0.0, 0.0, 0.00, 107.87, 0.5, 0.0, 0.0),
             "shelving": (2.80, 3.00, 1.57, 1.96, 99.90, 57.45, 29.02, 4.41, 4.46, 0.524)},
    "ours": {"placing": (2.36, 2.55, 1.44, 1.97, 99.34, 64.61, 41.91, 6.82, 6.35, 0.563),
             "stacking": (1.13, 1.22, 0.97, 1.59, 95.79, 84.54, 48.45, 14.76, 4.55, 0.687),
             "shelving": (2.15, 2.84, 1.63, 2.17, 99.48, 66.94, 52.74, 8.55, 10.06, 0.550)},
}

#: The columns a table may show the paper's value of (``tables.<name>.paper``).
PAPER_METRICS = (*PAPER_COLUMNS, "ds_per_vertex")


def paper_value(method: str, task: str, metric: str) -> float:
    """The paper's Table 1 value of ``metric`` (one of :data:`PAPER_METRICS`) for ``method`` (this project's
    config name of the row, e.g. ``"grasptta"``) on ``task``; NaN where the paper has no such row."""
    if metric not in PAPER_METRICS:
        raise ValueError(f"the paper's Table 1 has no column {metric!r} (one of {', '.join(PAPER_METRICS)})")
    row = _ROWS.get(method, {}).get(task)
    if row is None:
        return float("nan")
    if metric == "ds_per_vertex":
        return row[PAPER_COLUMNS.index("ds")] / MANO_VERTICES * 100
    return float(row[PAPER_COLUMNS.index(metric)])
