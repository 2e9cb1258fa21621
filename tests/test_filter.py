"""The prior-grasp filter keeps and rejects what its thresholds say."""

from __future__ import annotations

import numpy as np

import pytest

from tohgs.grasps.filter import FilterThresholds, check_screen, quality_flags, rejection_counts, screen_flags

LIMITS = np.stack([np.full((15, 3), -0.2), np.full((15, 3), 1.5)], -1)


def _flags(**over):
    base = dict(pv=np.array([1e-6]), sd=np.array([0.01]), contact_distance=np.array([0.001]),
                finger_pose=np.zeros((1, 45)), joint_limits=LIMITS, e_fc=np.array([0.1]),
                e_dis=np.array([0.001]), e_pen=np.array([0.0]), t=FilterThresholds())
    base.update(over)
    return quality_flags(**base)


def test_a_good_grasp_passes():
    f = _flags()
    assert f["passed"].tolist() == [True]
    assert rejection_counts(f) == {"pv": 0, "sd": 0, "contact": 0, "joints": 0, "energy": 0, "passed": 1}


def test_each_threshold_rejects_on_its_own():
    bad_joint = np.zeros((1, 45))
    bad_joint[0, 7] = 1.6
    cases = {
        "pv": dict(pv=np.array([4.5e-6])),
        "sd": dict(sd=np.array([0.031])),
        "contact": dict(contact_distance=np.array([0.006])),
        "joints": dict(finger_pose=bad_joint),
        "energy": dict(e_fc=np.array([0.31])),
    }
    for check, over in cases.items():
        f = _flags(**over)
        assert not f["passed"][0], check
        assert [c for c in ("pv", "sd", "contact", "joints", "energy") if not f[c][0]] == [check]
    assert _flags(e_dis=np.array([0.006]))["energy"].tolist() == [False]
    assert _flags(e_pen=np.array([0.002]))["energy"].tolist() == [False]


def test_thresholds_are_settings_and_batches_count():
    pv = np.array([1e-6, 3e-6, 5e-6])
    f = _flags(pv=pv, sd=np.full(3, 0.01), contact_distance=np.zeros(3), finger_pose=np.zeros((3, 45)),
               e_fc=np.zeros(3), e_dis=np.zeros(3), e_pen=np.zeros(3), t=FilterThresholds(max_pv=2e-6))
    assert f["passed"].tolist() == [True, False, False]
    assert rejection_counts(f)["pv"] == 2 and rejection_counts(f)["passed"] == 1


def test_the_screen_is_the_energy_and_joint_checks_and_unsimulated_grasps_cannot_pass():
    rng = np.random.default_rng(0)
    b = 200
    finger = rng.uniform(-0.3, 1.6, (b, 45)) * (rng.random((b, 1)) < 0.5)  # half within the limits
    args = dict(finger_pose=finger, joint_limits=LIMITS, e_fc=rng.random(b) * 2, e_dis=rng.random(b) * 0.04,
                e_pen=rng.random(b) * 0.01, t=FilterThresholds(max_fc=1.0, max_dis=0.02, max_pen=0.005))
    screened = screen_flags(**args)
    sd = np.where(screened, rng.random(b) * 0.06, np.nan)  # SD simulated for the screened grasps only
    f = quality_flags(pv=np.zeros(b), sd=sd, contact_distance=np.zeros(b), **args)
    np.testing.assert_array_equal(screened, f["energy"] & f["joints"])
    assert 20 < screened.sum() < 180
    assert not f["sd"][~screened].any() and not f["passed"][~screened].any()
    counts = rejection_counts(f, np.isfinite(sd))
    assert counts["unsimulated"] == (~screened).sum()
    assert counts["sd"] == (screened & (sd >= 0.03)).sum()  # SD failures among the simulated grasps only
    assert rejection_counts(f)["sd"] == (~f["sd"]).sum()  # without the mask: every grasp not shown stable


def test_filter_thresholds_looser_than_the_screen_are_refused():
    screen = {"max_fc": 1.0, "max_dis": 0.02, "max_pen": 0.005, "joint_tolerance": 0.0}
    check_screen(screen, FilterThresholds(max_fc=1.0, max_dis=0.02, max_pen=0.005, max_sd=0.05, max_pv=1e-5), "raw.zarr")
    check_screen(screen, FilterThresholds(max_fc=0.3, max_dis=0.005, max_pen=0.001), "raw.zarr")  # tighter
    check_screen(None, FilterThresholds(max_fc=9.0), "raw.zarr")  # every grasp was simulated
    with pytest.raises(ValueError, match=r"raw.zarr: SD was simulated only .* max_dis 0.03 > 0.02"):
        check_screen(screen, FilterThresholds(max_fc=1.0, max_dis=0.03, max_pen=0.005), "raw.zarr")
    with pytest.raises(ValueError, match=r"joint_tolerance 0.1 > 0.0"):
        check_screen(screen, FilterThresholds(max_fc=1.0, max_dis=0.02, max_pen=0.005, joint_tolerance=0.1), "raw.zarr")
