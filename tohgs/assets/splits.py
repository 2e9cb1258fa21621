"""The sizes of the train / val / test splits of an object set, and the check that a run's tasks get objects
in each.

Pure standard library: the workflow runs :func:`check_split_sizes` when Snakemake parses it, and parsing
needs no package beyond Snakemake's own (``snakemake --lint`` in a bare Snakemake environment). Which object
goes to which split is the catalog's job (:func:`tohgs.assets.objects.write_catalog`): the embedded sources'
objects by a seeded draw among themselves (:func:`tohgs.assets.objects.assign_splits`), a user folder's
objects each by :func:`name_split` (or all to the split ``objects.sources.dir.split`` pins).
"""

from __future__ import annotations

import hashlib

from tohgs.assets.sources import TASK_SET_BRICKS, TASK_SET_OBJECTS


def split_sizes(n: int, test_fraction: float, val_fraction: float) -> tuple[int, int, int]:
    """``(train, val, test)`` object counts of a set of ``n``: ``round(fraction x n)`` objects go to test (at
    least one when the fraction is positive and there are two or more objects), then to val, the rest to
    train (at least one where there are two or more objects)."""
    n_test = int(round(test_fraction * n))
    if test_fraction > 0 and n >= 2:
        n_test = max(n_test, 1)
    n_test = min(n_test, n - 1) if n >= 2 else 0
    n_val = min(int(round(val_fraction * n)), n - n_test - 1) if n - n_test >= 2 else 0
    return n - n_test - n_val, n_val, n_test


#: The ``objects.split`` key of each task set.
SPLIT_KEYS = {TASK_SET_OBJECTS: "objects", TASK_SET_BRICKS: "bricks"}


def check_split_sizes(counts: dict[str, int], split_cfg: dict[str, dict[str, float]], task_sets: list[str],
                      what: str = "selected", detail: str = "") -> None:
    """Every task set a run uses must give at least one training and one test object.

    Args:
        counts: objects per task set (``placing/shelving``, ``stacking``).
        split_cfg: ``objects.split``.
        task_sets: the task sets of the configured tasks.
        what: how the objects were counted ("selected" at parse time, "accepted" in the catalog).
        detail: appended to the message (e.g. the rejected objects and their reasons).

    Raises:
        ValueError: naming the split key, the counts and what to change.
    """
    for ts in task_sets:
        key = SPLIT_KEYS[ts]
        n = counts.get(ts, 0)
        frac = split_cfg[key]
        train, _, test = split_sizes(n, frac["test"], frac["val"])
        if test and train:
            continue
        missing = "test" if not test else "training"
        raise ValueError(f"objects.split.{key}: {n} {what} {ts} objects give {train} training and {test} test "
                         f"objects (test fraction {frac['test']}, val {frac['val']}); the tasks need at least one "
                         f"{missing} object: select more objects (objects.sources) or change objects.split.{key}"
                         + (f" ({detail})" if detail else ""))


def name_split(name: str, seed: int, test_fraction: float, val_fraction: float) -> str:
    """The split of one object by its name alone: ``test`` where a uniform number drawn from the name and
    ``seed`` (SHA-256) lies below ``test_fraction``, ``val`` below ``test_fraction + val_fraction``, else
    ``train``. Another object added or removed changes nothing here; the sizes of a set are binomial, not
    :func:`split_sizes`'."""
    u = int.from_bytes(hashlib.sha256(f"{seed}:{name}".encode()).digest()[:8], "big") / 2.0**64
    return "test" if u < test_fraction else "val" if u < test_fraction + val_fraction else "train"
