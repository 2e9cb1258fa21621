"""The hand interface on both backends: kinematics, gradients, mesh, labels, the MANO loader."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch
import trimesh

from tohgs.hand import HandAssets, HandModel, load_hand_assets
from tohgs.hand.layout import FINGERS, KEYPOINT_NAMES, PARENTS, descendants
from tohgs.hand.mano_backend import load_mano_assets, read_mano_pickle
from tohgs.hand.rotations import axis_angle_to_matrix, matrix_to_axis_angle

from synthetic_mano import make_synthetic_mano

load_hand_assets_file = HandAssets.load


@pytest.fixture(scope="session")
def anny_assets():
    return load_hand_assets("anny")  # built once, cached under ~/.cache/tohgs


@pytest.fixture(scope="session")
def hand(anny_assets):
    return HandModel(anny_assets, dtype=torch.float64)


@pytest.fixture(scope="session")
def mano_file(anny_assets, tmp_path_factory):
    path = tmp_path_factory.mktemp("mano") / "MANO_RIGHT.pkl"
    arrays = make_synthetic_mano(anny_assets, path)
    return path, arrays


@pytest.fixture(scope="session")
def mano_hand(mano_file):
    return HandModel(load_mano_assets(mano_file[0]), dtype=torch.float64)


def _random_pose(b, seed, scale=0.3):
    g = torch.Generator().manual_seed(seed)
    p = torch.randn(b, 51, generator=g, dtype=torch.float64) * scale
    p[:, :3] *= 0.1
    return p


def test_rotation_round_trip():
    aa = torch.randn(64, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    aa = aa / aa.norm(dim=1, keepdim=True) * torch.rand(64, 1, dtype=torch.float64) * 3.0
    r = axis_angle_to_matrix(aa)
    torch.testing.assert_close(r @ r.transpose(1, 2), torch.eye(3, dtype=torch.float64).expand(64, 3, 3))
    torch.testing.assert_close(matrix_to_axis_angle(r), aa, atol=1e-7, rtol=1e-6)
    assert torch.allclose(axis_angle_to_matrix(torch.zeros(1, 3)), torch.eye(3))


@pytest.mark.parametrize("which", ["hand", "mano_hand"])
def test_zero_pose_gives_the_rest_mesh(which, request):
    h = request.getfixturevalue(which)
    out = h(torch.zeros(3, 51, dtype=torch.float64))
    assert out.vertices.shape == (3, h.n_vertices, 3) and out.joints.shape == (3, 21, 3)
    torch.testing.assert_close(out.vertices[0], h.rest_vertices)
    torch.testing.assert_close(out.joints[0, :16], h.rest_joints)
    torch.testing.assert_close(out.joints[0, 16:], h.rest_vertices[h.tip_ids])


@pytest.mark.parametrize("which", ["hand", "mano_hand"])
def test_translation_adds_exactly(which, request):
    h = request.getfixturevalue(which)
    pose = _random_pose(4, 1)
    moved = pose.clone()
    t = torch.tensor([0.3, -0.2, 0.05], dtype=torch.float64)
    moved[:, :3] += t
    a, b = h(pose), h(moved)
    torch.testing.assert_close(b.vertices - a.vertices, t.expand_as(a.vertices), atol=1e-12, rtol=0)
    torch.testing.assert_close(b.joints - a.joints, t.expand_as(a.joints), atol=1e-12, rtol=0)


def test_global_rotation_turns_the_hand_about_the_wrist(hand):
    pose = torch.zeros(1, 51, dtype=torch.float64)
    pose[0, 3:6] = torch.tensor([0.3, -1.1, 0.7])
    r = axis_angle_to_matrix(pose[0, 3:6])
    j0 = hand.rest_joints[0]
    expect = (hand.rest_vertices - j0) @ r.T + j0
    torch.testing.assert_close(hand(pose).vertices[0], expect)


@pytest.mark.parametrize("joint", [2, 4, 9, 13, 15])
def test_a_finger_joint_moves_only_its_descendants(hand, joint):
    pose = torch.zeros(1, 51, dtype=torch.float64)
    pose[0, 3 + 3 * joint: 6 + 3 * joint] = torch.tensor([0.2, 0.3, 0.6])
    out = hand(pose)
    moved_joints = set(descendants(joint))
    d_joint = (out.joints[0, :16] - hand.rest_joints).norm(dim=1)
    for k in range(16):
        assert (d_joint[k] > 1e-6) == (k in moved_joints), f"joint {k}"
    influenced = hand.weights[:, [joint] + sorted(moved_joints)].sum(1) > 0
    d_vert = (out.vertices[0] - hand.rest_vertices).norm(dim=1)
    assert d_vert[~influenced].max() < 1e-12
    assert d_vert[influenced].max() > 1e-3


def test_gradients_match_finite_differences(hand):
    pose = _random_pose(2, 2).requires_grad_(True)
    betas = (0.5 * torch.randn(2, 10, dtype=torch.float64, generator=torch.Generator().manual_seed(3))).requires_grad_(True)
    sub = torch.randperm(hand.n_vertices, generator=torch.Generator().manual_seed(4))[:40]

    def f(p, b):
        out = hand(p, b)
        return out.vertices[:, sub], out.joints

    assert torch.autograd.gradcheck(f, (pose, betas), eps=1e-6, atol=1e-5)


def test_closed_mesh_is_watertight_with_positive_volume(hand, mano_hand):
    for h in (hand, mano_hand):
        m = trimesh.Trimesh(h.rest_vertices.numpy(), h.closed_faces.numpy(), process=False)
        assert m.is_watertight and m.is_winding_consistent
        assert m.volume > 1e-4  # > 100 cm^3, a human hand
        assert len(h.closed_faces) > len(h.faces)


def test_part_labels_contacts_and_tips(hand):
    a = hand.assets
    assert set(np.unique(a.part_labels)) == set(range(16))
    assert 70 <= len(a.contact_ids) <= 90 and len(set(a.contact_ids.tolist())) == len(a.contact_ids)
    per_finger = {f: int(np.isin(a.part_labels[a.contact_ids], ks).sum()) for f, ks in FINGERS.items()}
    assert per_finger == {"index": 17, "middle": 17, "pinky": 11, "ring": 17, "thumb": 14}
    assert int((a.part_labels[a.contact_ids] == 0).sum()) == 8
    normals = trimesh.Trimesh(a.rest_vertices, a.closed_faces, process=False).vertex_normals
    assert (normals[a.contact_ids] @ np.array([0.0, -1.0, 0.0]) > 0.5).all(), "a contact candidate off the palm side"
    # Fingertips: the farthest vertex of each finger from the wrist, roughly.
    assert len(KEYPOINT_NAMES) == 21
    tips = a.rest_vertices[a.tip_ids]
    assert (np.linalg.norm(tips - a.rest_joints[0], axis=1) > 0.09).all()


def test_canonical_frame_and_size(hand):
    j = hand.rest_joints.numpy()
    assert np.linalg.norm(j[0]) < 1e-9
    middle_tip = hand.rest_vertices[hand.tip_ids[2]].numpy()
    assert -0.21 < middle_tip[0] < -0.15, "fingers along -x, wrist to middle tip about 17.6 cm"
    assert hand.rest_vertices[hand.tip_ids[0], 2] > 0.04, "thumb on +z"
    power = hand(hand.preset("power").double()).joints[0].numpy()
    assert (power[[3, 6, 9, 12], 1] < j[[3, 6, 9, 12], 1] - 0.02).all(), "fingers curl toward -y (the palm)"


def test_presets_and_prior_within_joint_limits(hand):
    lim = hand.joint_limits.numpy()
    for name in ("flat", "relaxed", "power", "pinch"):
        p = hand.assets.presets[name][6:].reshape(15, 3)
        assert ((p >= lim[..., 0] - 1e-9) & (p <= lim[..., 1] + 1e-9)).all(), name
    assert (hand.prior_std > 0).all()
    with pytest.raises(KeyError, match="unknown pose preset 'fist'"):
        hand.preset("fist")


def test_same_inputs_same_outputs(hand):
    pose = _random_pose(5, 7)
    betas = 0.3 * torch.ones(5, 10, dtype=torch.float64)
    a, b = hand(pose, betas), hand(pose, betas)
    assert torch.equal(a.vertices, b.vertices) and torch.equal(a.joints, b.joints)


def test_shared_shape_fast_path_equals_the_general_path(hand):
    pose = _random_pose(6, 9).requires_grad_(True)
    a = hand(pose, None)
    b = hand(pose, torch.zeros(6, 10, dtype=torch.float64))
    torch.testing.assert_close(a.vertices, b.vertices, atol=1e-12, rtol=0)
    torch.testing.assert_close(a.joints, b.joints, atol=1e-12, rtol=0)
    weights = torch.randn(6, hand.n_vertices, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
    ga, gb = (torch.autograd.grad((o.vertices * weights).sum() + o.joints.sum(), pose)[0] for o in (a, b))
    torch.testing.assert_close(ga, gb, atol=1e-10, rtol=1e-10)
    assert a.vertices.transpose(1, 2).is_contiguous()  # coordinate-major: the optimiser's per-axis work streams


def test_skinning_rows_give_the_forward_pass_and_any_vertex_subset(hand, mano_hand):
    pose = _random_pose(7, 11)
    rows, joints16 = hand.skinning_rows(pose)
    out = hand(pose)
    v = (rows.reshape(-1, 65) @ hand.skin_rest_t).reshape(7, 3, -1).transpose(1, 2)
    assert torch.equal(v, out.vertices) and torch.equal(joints16, out.joints[:, :16])  # the same GEMM
    ids = torch.tensor([0, 5, 77, hand.n_vertices - 1])
    sub = (rows.reshape(-1, 65) @ hand.skin_rest_t[:, ids]).reshape(7, 3, -1).transpose(1, 2)
    torch.testing.assert_close(sub, out.vertices[:, ids], atol=1e-12, rtol=0)
    assert hand.linear_skinning and not mano_hand.linear_skinning
    with pytest.raises(ValueError, match="pose blend shapes"):
        mano_hand.skinning_rows(pose)


@pytest.mark.parametrize("which", ["hand", "mano_hand"])
def test_numpy_vertices_equal_the_torch_model(which, request):
    """HandAssets.vertices (torch-free jobs) poses the mesh exactly like HandModel, MANO's pose blend
    shapes included; zero angles and a single hand too."""
    model = request.getfixturevalue(which)
    pose = _random_pose(6, 11, scale=0.6)
    pose[0, 3:] = 0.0
    want = model(pose).vertices.numpy()
    got = model.assets.vertices(pose.numpy())
    assert got.shape == want.shape and got.dtype == np.float64
    np.testing.assert_allclose(got, want, atol=1e-12, rtol=0)
    np.testing.assert_allclose(model.assets.vertices(pose[2:3].numpy()), want[2:3], atol=1e-12, rtol=0)
    with pytest.raises(ValueError, match="51"):
        model.assets.vertices(np.zeros((2, 48)))


def test_hand_assets_load_without_torch():
    """Reading hand assets must not import torch (task-expansion jobs rely on it for their start-up)."""
    import subprocess
    import sys

    code = "import sys; from tohgs.hand import HandAssets, load_hand_assets; assert 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_assets_save_and_load(anny_assets, tmp_path):
    anny_assets.save(tmp_path / "hand.npz")
    back = load_hand_assets_file(tmp_path / "hand.npz")
    back.save(tmp_path / "again.npz")  # the same assets, the same bytes
    assert (tmp_path / "again.npz").read_bytes() == (tmp_path / "hand.npz").read_bytes()
    np.testing.assert_array_equal(back.rest_vertices, anny_assets.rest_vertices)
    assert sorted(back.presets) == sorted(anny_assets.presets)
    (tmp_path / "bad.npz").write_bytes(b"nope")
    with pytest.raises(ValueError, match="bad.npz"):
        load_hand_assets_file(tmp_path / "bad.npz")


def test_betas_change_the_shape(hand):
    z = torch.zeros(1, 51, dtype=torch.float64)
    scale = torch.zeros(1, 10, dtype=torch.float64)
    scale[0, 6] = 1.0  # hand scale
    big = hand(z, scale).vertices[0]
    assert (big.max(0).values - big.min(0).values).norm() > (hand.rest_vertices.max(0).values - hand.rest_vertices.min(0).values).norm()
    with pytest.raises(ValueError, match="betas must have shape"):
        hand(z, torch.zeros(1, 3, dtype=torch.float64))
    with pytest.raises(ValueError, match="pose must have shape"):
        hand(torch.zeros(1, 48, dtype=torch.float64))


def _reference_mano(arrays, pose, betas):
    """MANO's published equations, one vertex transform at a time (slow, obviously right)."""
    v = arrays["v_template"] + arrays["shapedirs"] @ betas
    jreg = arrays["J_regressor"].toarray()
    j = jreg @ v
    rots = [axis_angle_to_matrix(torch.as_tensor(pose[3 + 3 * k: 6 + 3 * k])).numpy() for k in range(16)]
    feat = np.concatenate([(r - np.eye(3)).ravel() for r in rots[1:]])
    v = v + arrays["posedirs"] @ feat
    g = []
    for k in range(16):
        local = np.eye(4)
        local[:3, :3] = rots[k]
        local[:3, 3] = j[k] - (j[PARENTS[k]] if k else 0)
        g.append(local if k == 0 else g[PARENTS[k]] @ local)
    a = [gk @ np.block([[np.eye(3), -j[k][:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]) for k, gk in enumerate(g)]
    out = np.zeros_like(v)
    for i in range(len(v)):
        t = sum(arrays["weights"][i, k] * a[k] for k in range(16))
        out[i] = (t @ np.r_[v[i], 1.0])[:3]
    return out + pose[:3]


def test_mano_backend_matches_the_published_equations(mano_file, mano_hand):
    path, arrays = mano_file
    pose = _random_pose(1, 11)[0].numpy()
    betas = np.linspace(-1, 1, 10)
    got = mano_hand(torch.as_tensor(pose)[None], torch.as_tensor(betas)[None]).vertices[0].numpy()
    np.testing.assert_allclose(got, _reference_mano(arrays, pose, betas), atol=1e-10)


def test_mano_file_round_trips(mano_file):
    path, arrays = mano_file
    d = read_mano_pickle(path)
    np.testing.assert_array_equal(d["shapedirs"], arrays["shapedirs"])  # chumpy object -> plain array
    np.testing.assert_array_equal(d["J_regressor"], arrays["J_regressor"].toarray())
    np.testing.assert_array_equal(d["v_template"], arrays["v_template"])


def test_malicious_pickle_is_refused(tmp_path):
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            import os
            return (os.system, (f"touch {marker}",))

    bad = tmp_path / "MANO_RIGHT.pkl"
    bad.write_bytes(pickle.dumps({"v_template": Evil()}, protocol=2))
    with pytest.raises(ValueError, match="refusing global '(posix|os).system'"):
        read_mano_pickle(bad)
    assert not marker.exists()


def test_missing_or_malformed_mano_file_names_the_path(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere.pkl"):
        load_mano_assets(tmp_path / "nowhere.pkl")
    junk = tmp_path / "junk.pkl"
    junk.write_bytes(b"this is not a pickle")
    with pytest.raises(ValueError, match="junk.pkl"):
        load_mano_assets(junk)
    partial = tmp_path / "partial.pkl"
    partial.write_bytes(pickle.dumps({"v_template": np.zeros((10, 3))}, protocol=2))
    with pytest.raises(ValueError, match="partial.pkl: missing keys"):
        load_mano_assets(partial)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu(anny_assets):
    cpu = HandModel(anny_assets)
    gpu = HandModel(anny_assets).to("cuda")
    pose = _random_pose(8, 5).float()
    torch.testing.assert_close(gpu(pose.cuda()).vertices.cpu(), cpu(pose).vertices, atol=1e-5, rtol=1e-5)
