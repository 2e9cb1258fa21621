"""Bad input that once got past without a word (the cases of the issue "What bad input still gets past"): damaged
object files, non-finite settings, reserved replica names, unsafe file names, oversized meshes, a checkpoint of
another task, store attributes outside the manifest, a YAML "billion laughs". Each is refused or skipped with a
message that names the file or the key. The official importer's cases are in ``tests/test_official.py``.
"""

from __future__ import annotations

import time

import pytest
import yaml

from tohgs.config import SEED_MAX, ConfigError, _finite_numbers, validate_config

# ---------------------------------------------------------------------------------------------------------
# Settings: non-finite numbers, seeds beyond int64, replica names, a YAML billion laughs.


@pytest.mark.parametrize(("patch", "key"), [
    ({"evaluation": {"qr": {"max_sd": float("nan")}}}, "evaluation.qr.max_sd"),
    ({"prior_grasps": {"filter": {"max_sd": float("nan")}}}, "prior_grasps.filter.max_sd"),
    ({"training": {"lr": float("nan")}}, "training.lr"),
    ({"objects": {"size": {"longest_min": float("nan")}}}, "objects.size.longest_min"),
    ({"evaluation": {"qr_grid": {"max_sd": [0.01, float("inf")]}}}, "evaluation.qr_grid.max_sd.1"),
    ({"components": {"grasp_diffuser": {"training": {"lr": float("-inf")}}}}, "components.grasp_diffuser.training.lr"),
])
def test_a_non_finite_number_is_a_config_error_naming_its_key(patch, key):
    with pytest.raises(ConfigError, match=rf"config key '{key}': (nan|inf|-inf) is not a finite number"):
        validate_config(patch)


def test_the_schema_may_allow_non_finite_numbers_below_a_marked_key():
    schema = {"type": "object", "properties": {"a": {"type": "number"}, "b": {"type": "number", "x-nonfinite": True}}}
    _finite_numbers({"a": 1.0, "b": float("inf")}, schema)
    with pytest.raises(ConfigError, match="config key 'a'"):
        _finite_numbers({"a": float("nan"), "b": 1.0}, schema)


@pytest.mark.parametrize(("patch", "key"), [
    ({"seed": 2**64}, "seed"),
    ({"seeds": [0, 2**63]}, "seeds.1"),
    ({"evaluation": {"robust_sd": {"seed": -1}}}, "evaluation.robust_sd.seed"),
    ({"seeds": [0, 2**62], "training": {"seed": 2**62}}, "training.seed"),
    ({"seeds": [0, 2**62], "methods": {"ours": {"settings": {"seed": 2**62}}}}, "methods.ours.settings.seed"),
])
def test_a_seed_beyond_the_signed_64_bit_range_is_a_config_error(patch, key):
    with pytest.raises(ConfigError, match=rf"config key '{key}'.*(out of range|beyond the largest seed)"):
        validate_config(patch)
    validate_config({"seed": SEED_MAX, "seeds": [0, 1], "training": {"seed": SEED_MAX - 1}})  # the bound itself


@pytest.mark.parametrize(("patch", "key"), [
    ({"methods": {"ours-seed1": {"label": "Mine", "kind": "reference"}}, "seeds": [0, 1]}, "methods.ours-seed1"),
    ({"components": {"grasp_diffuser-seed1": {"kind": "grasp_diffuser"}}}, "components.grasp_diffuser-seed1"),
])
def test_a_name_like_a_seed_replica_is_a_config_error_that_says_why(patch, key):
    with pytest.raises(ConfigError, match=rf"config key '{key}': names ending in '-seed<k>' are reserved for the seed "
                                          r"replicas .* rename it"):
        validate_config(patch)
    validate_config({"methods": {"ours-seedless": {"label": "Mine", "kind": "reference"}}})  # only -seed<digits>


def test_a_yaml_billion_laughs_is_refused_before_anything_iterates_over_it():
    levels = ["l0: &l0 [" + ", ".join(["ours"] * 10) + "]"]
    levels += [f"l{k}: &l{k} [" + ", ".join([f"*l{k - 1}"] * 10) + "]" for k in range(1, 7)]
    text = "anchors:\n" + "".join(f"  {line}\n" for line in levels) + "figures:\n  comparisons:\n    laugh: *l6\n"
    cfg = yaml.safe_load(text)  # aliases load as shared references: cheap
    del cfg["anchors"]
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match=r"config key 'figures\.comparisons\.laugh': the configuration holds more "
                                          r"than 200000 values"):
        validate_config(cfg)
    assert time.perf_counter() - t0 < 5.0
