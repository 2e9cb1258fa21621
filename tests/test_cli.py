"""The tohgs command: every subcommand reaches its module's main, unknown ones are refused with the list."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

from tohgs.cli import COMMANDS, main

REPO = Path(__file__).resolve().parent.parent


def test_every_subcommand_is_a_modules_main(capsys):
    for module, _ in COMMANDS.values():
        assert callable(importlib.import_module(module).main), module
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in COMMANDS)
    assert main(["frobnicate"]) == 2 and "unknown command 'frobnicate'" in capsys.readouterr().err
    assert main(["check-config", str(REPO / "config" / "extras.yaml")]) == 0


def test_the_installed_script_runs():
    script = Path(sys.executable).parent / "tohgs"
    assert script.is_file(), "pip install -e . installs the tohgs command (pyproject.toml [project.scripts])"
    run = subprocess.run([str(script), "export", "--help"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and "--format" in run.stdout
