"""The library as it was at another commit, importable next to the working tree's: ``git archive`` of the
commit's ``tohgs/`` unpacked into a temporary folder as the package ``tohgs_base`` (every ``tohgs``
import inside it renamed), so that a benchmark runs the old and the new code path in one process,
interleaved, on the same inputs.

Both packages build their own objects; the networks and the hand model passed between them are the
working tree's (an old function calls their methods, which the optimisers' speed work leaves as they were:
:meth:`tohgs.models.contact_net.ContactNet.predict_map`, the hand's forward pass).
"""

from __future__ import annotations

import atexit
import importlib
import io
import platform
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path
from types import ModuleType

REPO = Path(__file__).resolve().parent.parent
BASE_COMMIT = "5a27373"  # main before the optimisers' per-hand speed work (issue 38)
_IMPORT = re.compile(r"\b(from|import)(\s+)tohgs(?=[.\s])")


def base_package(commit: str = BASE_COMMIT, name: str = "tohgs_base") -> ModuleType:
    """Import ``commit``'s ``tohgs`` as the package ``name`` (unpacked once per process) and return it."""
    if name in sys.modules:
        return sys.modules[name]
    archive = subprocess.run(["git", "archive", commit, "tohgs"], cwd=REPO, capture_output=True, check=True).stdout
    root = Path(tempfile.mkdtemp(prefix=f"{name}-"))
    atexit.register(shutil.rmtree, root, True)
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(root, filter="data")
    (root / "tohgs").rename(root / name)
    for path in (root / name).rglob("*.py"):
        text = path.read_text()
        text = _IMPORT.sub(lambda m: f"{m.group(1)}{m.group(2)}{name}", text)
        path.write_text(text.replace("tohgs.", f"{name}."))
    sys.path.insert(0, str(root))
    return importlib.import_module(name)


def base_module(module: str, commit: str = BASE_COMMIT) -> ModuleType:
    """``commit``'s version of the module ``module`` (``tohgs.grasps.tta`` etc.)."""
    base_package(commit)
    return importlib.import_module(module.replace("tohgs", "tohgs_base", 1))


def short_commit(ref: str = "HEAD") -> str:
    """The short hash of ``ref`` in this repository."""
    return subprocess.run(["git", "rev-parse", "--short", ref], cwd=REPO, capture_output=True, text=True).stdout.strip()


def commit_label() -> str:
    """The short hash of HEAD, with ``-dirty`` where tracked files differ from it ("unknown" without git): what
    a benchmark's JSON records as the code it measured."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO, capture_output=True,
                               text=True, check=True).stdout.strip()
        return head + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo``, else :func:`platform.processor`): machines of one kind differ
    1.5-1.7x in speed, so a benchmark's JSON names the CPU it ran on."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()
