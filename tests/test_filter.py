"""The prior-grasp filter keeps and rejects what its thresholds say."""

from __future__ import annotations

import numpy as np

from tohgs.grasps.filter import FilterThresholds, quality_flags, rejection_counts

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
