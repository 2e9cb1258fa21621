"""Shared fixtures: the repository root, config loading and the end-to-end smoke run."""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


@pytest.fixture()
def default_config() -> dict:
    """A fresh copy of the embedded default config (config/config.yaml), unvalidated."""
    with open(REPO / "config" / "config.yaml") as fh:
        return copy.deepcopy(yaml.safe_load(fh))


@pytest.fixture(scope="session")
def smoke_run(tmp_path_factory) -> Path:
    """A finished smoke run (``.test/config/config.yaml``) in a copy of the workflow: its folder, with
    ``results/`` and ``logs/``. Once per session: tests/test_viewer.py reads it, tests/test_workflow.py reads it
    and reruns parts of it."""
    from workflow_tools import copy_workflow, workflow_env

    work = copy_workflow(tmp_path_factory.mktemp("smoke"))
    cmd = [sys.executable, "-m", "snakemake", "--cores", "2", "--configfile", ".test/config/config.yaml"]
    out = subprocess.run(cmd, cwd=work, capture_output=True, text=True, timeout=1800, env=workflow_env(work))
    assert out.returncode == 0, (out.stdout + out.stderr)[-5000:]
    return work
