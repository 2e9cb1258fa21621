"""Helpers of the tests that run the workflow in a copy: the copy, its environment, a dry run's job counts."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
#: What a run of the workflow needs from the checkout.
WORKFLOW_PARTS = ("workflow", "config", "tohgs", ".test", "profiles")


def copy_workflow(dest: Path) -> Path:
    """Copy the workflow, configs, library and profiles into ``dest`` (created); returns ``dest``."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for d in WORKFLOW_PARTS:
        shutil.copytree(REPO / d, dest / d, ignore=ignore)
    return dest


def workflow_env(workdir: Path) -> dict[str, str]:
    """The environment of a run in ``workdir``: the jobs import the copy's library, not the checkout's (an
    editable install points there)."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(workdir), os.environ.get("PYTHONPATH")]))}


def job_stats(text: str) -> dict[str, int]:
    """{rule: number of jobs} of the first "Job stats" table in a Snakemake output ({} when it has none)."""
    if "Job stats:" not in text:
        return {}
    counts: dict[str, int] = {}
    for line in text.split("Job stats:", 1)[1].splitlines():
        m = re.match(r"^(\w+)\s+(\d+)$", line.strip())
        if m and m.group(1) == "total":
            break
        if m:
            counts[m.group(1)] = int(m.group(2))
    return counts
