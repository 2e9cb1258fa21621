"""The code a rule's jobs run (tohgs/code_inputs.py), derived from the imports of its script: a static check,
no workflow run (moved out of tests/test_workflow.py, whose end-to-end runs are marked slow)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tohgs.code_inputs import code_inputs

REPO = Path(__file__).resolve().parent.parent


def test_the_code_inputs_are_derived_from_the_imports(tmp_path):
    """The modules a script reaches through others count (task expansion reads the hand's assets and the
    supports; a prediction loads its method's and its components' kinds by name), and so do lazy imports."""

    def listed(script, *modules):
        return {f.relative_to(REPO).as_posix() for f in code_inputs(REPO / "workflow/scripts" / script, modules, REPO)}

    assert {"tohgs/hand/assets.py", "tohgs/assets/supports.py", "tohgs/geometry/scene.py", "tohgs/data/store.py",
            "tohgs/__init__.py"} <= listed("task_grasps.py")
    assert {"tohgs/hand/assets.py", "tohgs/metrics/quality.py"} <= listed("evaluate.py")
    assert "tohgs/models/grasp_diffuser.py" not in listed("predict.py")
    assert {"tohgs/methods/contact_grasp.py", "tohgs/models/grasp_diffuser.py", "tohgs/hand/model.py"} <= listed(
        "predict.py", "methods/contact_grasp", "models/grasp_diffuser")
    # a lazy import inside a function is code the job may run
    pkg = tmp_path / "tohgs"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from tohgs import b\n    return b\n")
    (pkg / "b.py").write_text("import numpy\n")
    (tmp_path / "s.py").write_text("import tohgs.a\n")
    assert {f.name for f in code_inputs(tmp_path / "s.py", (), tmp_path)} == {"__init__.py", "a.py", "b.py"}
    with pytest.raises(FileNotFoundError, match="no module"):
        code_inputs(tmp_path / "s.py", ("models/nothing",), tmp_path)


#: The stages before training (their rule files): their jobs are the costliest to rerun.
DATA_STAGES = ("hand", "objects", "scenes", "grasps", "dataset", "official")
#: What a data job must not run: the config validator (the workflow's) and the method and component registries.
NOT_DATA_CODE = {"tohgs/config.py", "tohgs/methods/__init__.py", "tohgs/models/__init__.py"}


def test_the_data_stages_run_neither_the_validator_nor_a_registry():
    """An edit of a schema check or of a registry leaves the data stages be: every script of their rules
    reaches neither (the settings dataclasses are built by tohgs.settings, a leaf); nor does a prediction job
    run the training loop (the device is picked beside the checkpoint loader)."""
    scripts = sorted({s for stage in DATA_STAGES
                      for s in re.findall(r'"\.\./scripts/(\w+\.py)"', (REPO / f"workflow/rules/{stage}.smk").read_text())})
    assert {"prior_synthesis.py", "prior_filter.py", "scenes.py", "maps.py", "task_grasps.py"} <= set(scripts)
    for script in scripts:
        listed = {f.relative_to(REPO).as_posix() for f in code_inputs(REPO / "workflow/scripts" / script, (), REPO)}
        assert not listed & NOT_DATA_CODE, f"{script} runs {sorted(listed & NOT_DATA_CODE)}"
    predict = code_inputs(REPO / "workflow/scripts/predict.py", ("methods/grasp_tta", "models/grasp_cvae"), REPO)
    assert not {"tohgs/models/train.py", "tohgs/config.py"} & {f.relative_to(REPO).as_posix() for f in predict}
