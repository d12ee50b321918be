"""K-Planes interpolation against hand-computed values and grid_sample; initialisation; SH; 1D grid."""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from stages.model import encodings
from stages.model.encodings import (
    Grid1DEncoding,
    KPlanesEncoding,
    MultiScaleKPlanes,
    SHEncoding,
    all_pairs,
    axis_cells,
    rows_from_cells,
)


def bilinear_rows(stack: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    """grid_sample's call (bilinear, border, align_corners) on [G, N, 1, 2] grids, as bags of rows: [G, N, C]."""
    _, _, height, width = stack.shape
    along_w, along_h = axis_cells(grid[:, :, 0, 0], width), axis_cells(grid[:, :, 0, 1], height)
    return rows_from_cells(stack, [(along_w[:, g], along_h[:, g]) for g in range(stack.shape[0])])


def test_single_plane_bilinear_matches_hand_computation():
    enc = KPlanesEncoding([3, 3], channels=1, pairs=[(0, 1)], spatial_dims=2)
    # plane[row = y index, col = x index]; vertices at -1, 0, 1 (align_corners)
    values = torch.tensor([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
    with torch.no_grad():
        enc.planes[0].copy_(values.view(1, 1, 3, 3))
    # x = 0.5 -> column 1.5, y = -0.5 -> row 0.5: bilinear of 2, 3, 5, 6 at (0.5, 0.5) = 4.0
    out = enc(torch.tensor([[0.5, -0.5]]))
    assert out.shape == (1, 1)
    assert out.item() == pytest.approx(4.0)
    # corner and centre vertices are returned exactly
    assert enc(torch.tensor([[-1.0, -1.0], [0.0, 0.0], [1.0, 1.0]]))[:, 0].tolist() == pytest.approx([1, 5, 9])


def test_product_over_planes_and_non_spatial_init():
    enc = KPlanesEncoding([4, 4, 4, 5], channels=3, spatial_dims=3, init_range=(0.1, 0.5))
    assert enc.pairs == all_pairs(4) and len(enc.pairs) == 6
    # planes xk, yk, zk start at 1; spatial planes uniform in [0.1, 0.5]
    assert enc.k_plane_indices == [2, 4, 5]
    for i, p in enumerate(enc.planes):
        if i in enc.k_plane_indices:
            assert torch.all(p == 1)
        else:
            assert p.min() >= 0.1 and p.max() <= 0.5
    with torch.no_grad():
        for i, p in enumerate(enc.planes):
            p.fill_(float(i + 1))  # constant planes: the feature is the product 1*2*...*6 = 720
    assert torch.allclose(enc(torch.rand(7, 4) * 2 - 1), torch.full((7, 3), 720.0))


def test_multiscale_concatenates_and_keeps_k_resolution():
    enc = MultiScaleKPlanes([8, 8, 8, 6], channels=4, scales=[1, 2])
    assert enc.out_dim == 8
    assert enc(torch.zeros(5, 4)).shape == (5, 8)
    fine = enc.grids[1]
    assert fine.resolution == [16, 16, 16, 6]
    # an xk plane is stored [1, C, res_k, res_x]
    assert tuple(fine.planes[2].shape) == (1, 4, 6, 16)


def test_sh_encoding_known_values_and_orthonormality():
    sh = SHEncoding(4)
    up = sh(torch.tensor([[0.0, 0.0, 1.0]]))[0]
    assert up[0].item() == pytest.approx(0.5 / math.sqrt(math.pi))
    assert up[2].item() == pytest.approx(0.48860251190291987)
    assert up[1].item() == 0 and up[3].item() == 0
    # Monte-Carlo orthonormality over the sphere: E[Y Y^T] * 4 pi = I
    g = torch.Generator().manual_seed(0)
    d = torch.nn.functional.normalize(torch.randn(200000, 3, generator=g), dim=-1)
    y = sh(d)
    gram = (y.T @ y) / d.shape[0] * 4 * math.pi
    assert torch.allclose(gram, torch.eye(16), atol=0.03)


def test_grid1d_interpolates_linearly():
    g = Grid1DEncoding(resolution=4, channels=1)
    with torch.no_grad():
        g.values.copy_(torch.tensor([[0.0], [1.0], [4.0], [9.0], [16.0]]))
    out = g(torch.tensor([0.0, 0.125, 0.5, 1.0]))[:, 0]
    assert out.tolist() == pytest.approx([0.0, 0.5, 4.0, 16.0])


@pytest.mark.parametrize("shape", [(3, 16, 64, 64), (3, 16, 16, 32), (2, 4, 2, 2), (1, 3, 1, 5), (3, 8, 7, 1),
                                   (2, 2, 33, 17), (1, 37, 9, 9), (1, 128, 5, 6)])
def test_bilinear_rows_is_grid_sample_bit_for_bit(shape):
    torch.manual_seed(sum(shape))
    stack = torch.randn(*shape).contiguous(memory_format=torch.channels_last)
    n = 4099  # not a multiple of any vector width: grid_sample's scalar tail is compared too
    grid = torch.rand(shape[0], n, 1, 2) * 3 - 1.5  # inside and beyond the border
    # vertices, cell edges, the border itself and non-finite coordinates
    special = torch.tensor([-1.0, 1.0, 0.0, -0.5, 0.5, 1.0 - 1e-7, -1.0 + 1e-7, float("inf"), float("-inf"),
                            float("nan")])
    grid[:, : special.numel() ** 2, 0, 0] = special.repeat_interleave(special.numel())
    grid[:, : special.numel() ** 2, 0, 1] = special.repeat(special.numel())
    expected = F.grid_sample(stack, grid, mode="bilinear", padding_mode="border", align_corners=True)[..., 0]
    got = bilinear_rows(stack, grid)
    assert got.shape == (shape[0], n, shape[1])
    assert torch.equal(got.permute(0, 2, 1), expected)


def test_encodings_sample_rows_without_a_graph_and_grid_sample_with_one(monkeypatch):
    torch.manual_seed(0)
    enc = MultiScaleKPlanes([8, 8, 8, 6], channels=4, scales=[1, 2])
    with torch.no_grad():
        for g in enc.grids:
            for stack in g.plane_groups:
                stack.uniform_(0.5, 1.5)
    coords = torch.rand(1000, 4) * 2 - 1
    calls = []
    real = encodings.rows_from_cells
    monkeypatch.setattr(encodings, "rows_from_cells", lambda *a: calls.append(1) or real(*a))
    with_graph = enc(coords)
    assert not calls and with_graph.requires_grad  # training: grid_sample, whose backward the planes need
    with torch.no_grad():
        without = enc(coords)
    assert len(calls) == 4  # two scales x (spatial, k) plane groups
    assert torch.equal(without, with_graph.detach())
    with torch.inference_mode():
        assert torch.equal(enc.grids[0](coords), enc.grids[0].forward_cn(coords).transpose(0, 1))
    # one-channel planes stay with grid_sample (embedding_bag rounds a one-column table differently)
    narrow = KPlanesEncoding([8, 8, 8], channels=1, spatial_dims=3)
    calls.clear()
    with torch.no_grad():
        assert torch.equal(narrow(coords[:, :3]), narrow.forward_cn(coords[:, :3]).transpose(0, 1))
    assert not calls


def test_fields_sharing_a_cache_cut_each_axis_once_with_the_same_bits(monkeypatch):
    # a level's tri-plane and radiance scales read x, y, z (and k) at shared resolutions: one set of cells each
    torch.manual_seed(1)
    radiance = MultiScaleKPlanes([8, 8, 8, 6], channels=4, scales=[1, 2])
    triplane = KPlanesEncoding([8, 8, 8], channels=3, spatial_dims=3)
    with torch.no_grad():
        for g in [*radiance.grids, triplane]:
            for stack in g.plane_groups:
                stack.uniform_(0.5, 1.5)
    coords = torch.rand(777, 4) * 2.2 - 1.1
    cuts = []
    real = encodings.axis_cells
    monkeypatch.setattr(encodings, "axis_cells", lambda values, size: cuts.append(size) or real(values, size))
    cache: dict = {}
    with torch.no_grad():
        shared = (triplane(coords[:, :3], cache), radiance(coords, cache))
    assert sorted(cuts) == [6, 8, 8, 8, 16, 16, 16]  # x, y, z at 8 and 16 vertices, k at 6: once each
    assert torch.equal(shared[0], triplane.forward_cn(coords[:, :3]).transpose(0, 1))
    expected = torch.cat([g.forward_cn(coords) for g in radiance.grids], dim=0).transpose(0, 1)
    assert torch.equal(shared[1], expected)


def test_bilinear_rows_indexes_planes_of_more_than_2_24_vertices():
    # vertex numbers from 2**24 on are not exact in float32: the int64 index path, against grid_sample
    side = 4100  # 4100**2 > 2**24
    stack = torch.rand(1, 2, side, side).contiguous(memory_format=torch.channels_last)
    # odd vertex numbers above 2**24 (x0 = 4097, y0 = 4098) round to a neighbour in float32
    grid = torch.tensor([[0.9992, 0.9999], [0.9982, 0.9996], [1.0, 1.0], [-1.0, 1.0], [0.3, -0.7]]).view(1, 5, 1, 2)
    expected = F.grid_sample(stack, grid, mode="bilinear", padding_mode="border", align_corners=True)[..., 0]
    assert torch.equal(bilinear_rows(stack, grid).permute(0, 2, 1), expected)


def test_gradients_equal_a_plane_by_plane_product():
    """The stacked sampling (one grid_sample per stack, planes taken by unbind, output by squeeze) gives the
    gradients of sampling each plane alone and multiplying, for the planes and for a k coordinate that needs one."""
    torch.manual_seed(0)
    enc = KPlanesEncoding([6, 5, 7, 4], channels=3, spatial_dims=3)
    with torch.no_grad():
        for p in enc.plane_groups:
            p.uniform_(0.5, 1.5)
    coords = (torch.rand(40, 4) * 2 - 1).requires_grad_(True)
    weights = torch.randn(40, 3)
    (enc(coords) * weights).sum().backward()
    stacked = [p.grad.clone() for p in enc.plane_groups], coords.grad.clone()
    enc.zero_grad(set_to_none=True)
    coords.grad = None
    out = torch.ones(3, 40)
    for (a, b), plane in zip(enc.pairs, enc.planes, strict=True):
        # only the spatial planes' grids are detached (the fields' positions need no gradient; k may)
        grid = torch.stack((coords[:, a], coords[:, b]), dim=-1).view(1, 40, 1, 2)
        grid = grid if b >= 3 else grid.detach()
        out = out * F.grid_sample(plane, grid, mode="bilinear", padding_mode="border", align_corners=True)[0, :, :, 0]
    (out.t() * weights).sum().backward()
    for got, want in zip(stacked[0], [p.grad for p in enc.plane_groups], strict=True):
        torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(stacked[1], coords.grad, rtol=1e-5, atol=1e-6)
    assert stacked[1][:, 3].abs().sum() > 0
