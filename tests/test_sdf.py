"""Grid signed distances against the exact distance, gradients, and far queries."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tohgs.assets.bricks import make_brick
from tohgs.geometry.raycast import exact_signed_distance
from tohgs.geometry.sdf import SDFGrid


@pytest.fixture(scope="module")
def arch():
    m = make_brick("arch")
    m.apply_translation(-m.center_mass)
    return m, SDFGrid.build(m, spacing=0.002, padding=0.02)


def test_grid_matches_the_exact_distance(arch):
    mesh, grid = arch
    rng = np.random.default_rng(0)
    pts = rng.uniform(mesh.bounds[0] - 0.015, mesh.bounds[1] + 0.015, size=(5000, 3))
    exact = exact_signed_distance(mesh, pts)
    got = grid(torch.as_tensor(pts, dtype=torch.float32)).numpy()
    err = np.abs(got - exact)
    assert np.median(err) < 2e-4 and err.max() < 2e-3  # the arch's hole has sharp edges
    near = np.abs(exact) < 0.005
    assert np.sign(got[near & (np.abs(exact) > 0.002)]).tolist() == np.sign(exact[near & (np.abs(exact) > 0.002)]).tolist()


def test_gradient_is_the_outward_normal_near_a_face(arch):
    mesh, grid = arch
    top = mesh.bounds[1, 2]
    p = torch.tensor([[0.02, 0.0, top + 0.004]], requires_grad=True)  # above the top face of the arch
    grid(p).sum().backward()
    np.testing.assert_allclose(p.grad[0].numpy(), [0, 0, 1], atol=0.05)


def test_far_points_get_at_least_their_distance_to_the_grid(arch):
    mesh, grid = arch
    far = torch.tensor([[1.0, 0.0, 0.0], [0.0, -0.5, 0.0]])
    exact = exact_signed_distance(mesh, far.numpy())
    got = grid(far).numpy()
    np.testing.assert_allclose(got, exact, rtol=0.05)
    assert grid(far).shape == (2,)
    assert grid(torch.zeros(4, 7, 3)).shape == (4, 7)


def test_save_and_load(arch, tmp_path):
    _, grid = arch
    grid.save(tmp_path / "sdf.npz")
    back = SDFGrid.load(tmp_path / "sdf.npz")
    assert torch.equal(back.values, grid.values) and back.spacing == grid.spacing
    (tmp_path / "bad.npz").write_text("no")
    with pytest.raises(ValueError, match="bad.npz"):
        SDFGrid.load(tmp_path / "bad.npz")


def test_lower_bound_bounds_the_interpolated_distance(arch):
    mesh, grid = arch
    pts = torch.as_tensor(np.random.default_rng(3).uniform(mesh.bounds[0] - 0.03, mesh.bounds[1] + 0.03, (4000, 3)),
                          dtype=torch.float32)
    exact = grid(pts)
    bound = grid.lower_bound(pts)
    assert (bound <= exact + 1e-6).all()
    torch.testing.assert_close(grid.lower_bound(pts.reshape(40, 100, 3)), bound.reshape(40, 100))  # any batch shape
    in_grid = ((pts >= grid.origin) & (pts <= grid.upper)).all(-1)
    assert in_grid.sum() > 1000 and (~in_grid).sum() > 1000
    assert (exact - bound)[in_grid].max() < 2 * 3**0.5 * grid.spacing  # a tight bound inside the grid


@pytest.mark.parametrize("layout", ["points-major", "coordinate-major"])
def test_penetration_equals_the_dense_sum_and_its_gradient(arch, layout):
    mesh, grid = arch
    rng = np.random.default_rng(4)
    centre = mesh.bounds.mean(0)
    pts = torch.as_tensor(centre + rng.normal(0, 0.03, (6, 500, 3)), dtype=torch.float32)
    pts[:, :20] += 0.1  # some beyond the grid
    a = pts.clone().requires_grad_(True)
    dense = torch.relu(-grid(a)).sum(-1)
    (ga,) = torch.autograd.grad(dense.sum(), a)
    b = pts.clone() if layout == "points-major" else pts.transpose(1, 2).contiguous()  # (6, 3, 500)
    b.requires_grad_(True)
    view = b if layout == "points-major" else b.transpose(1, 2)  # (6, 500, 3) either way
    sparse = grid.penetration(view)
    (gb,) = torch.autograd.grad(sparse.sum(), b)
    assert (dense > 0).all()  # the clouds do sink in
    torch.testing.assert_close(sparse, dense)
    torch.testing.assert_close(gb if layout == "points-major" else gb.transpose(1, 2), ga)
    assert gb.is_contiguous()  # the gradient is built in the points' own layout
