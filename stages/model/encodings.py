"""Feature encodings: multi-scale K-Planes over any axis pairs, spherical harmonics, 1D grids.

K-Planes (Fridovich-Keil et al. 2023) factorises an N-D feature grid into 2D
planes, one per chosen pair of axes; a point's feature is the Hadamard product
of its bilinear samples on every plane. Planes that touch a non-spatial axis
(k, time, a state) start at 1, the product's identity, so a fresh field is
independent of that axis; spatial planes start uniform in a small range.
LiveScene uses the six planes of (x, y, z, k); the MK-Planes baselines use
other pair lists of (x, y, z, k_1..k_alpha), hence ``pairs`` is free.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence

import torch
import torch.nn.functional as F
from torch import nn


def all_pairs(n_dims: int) -> list[tuple[int, int]]:
    """Every axis pair of an ``n_dims`` coordinate: 4D -> xy, xz, xk, yz, yk, zk."""
    return list(itertools.combinations(range(n_dims), 2))


PlaneGrids = dict[tuple, torch.Tensor]
"""What sampling one batch of points needs, built once and shared by every field and scale that reads it:
grids [G, N, 1, 2] by the axis pairs they hold (the spatial xy, xz, yz grid of one level serves the
probability tri-plane, every scale of the radiance field and the proposal field), and, without a graph on a
CPU, ``axis_cells`` by ``("cells", axis, vertices)``."""


def plane_grid(coords: torch.Tensor, pairs: Sequence[tuple[int, int]], detach: bool,
               cache: PlaneGrids | None = None) -> torch.Tensor:
    """``coords`` [N, D] -> the grid [G, N, 1, 2] of the G axis ``pairs``, memoised in ``cache``.

    A cache belongs to one set of points: every coordinate array handed to it
    must agree on the axes its pairs read (positions first, then k or states).
    """
    key = tuple(pairs)
    if cache is not None and key in cache:
        return cache[key]
    # contiguous (a strided grid makes grid_sample 4x slower); stacking columns is 5x faster than coords[:, cols]
    grid = torch.stack([torch.stack((coords[:, a], coords[:, b]), dim=-1) for a, b in pairs]).unsqueeze(2)
    if detach:
        # positions never need a gradient; without it grid_sample skips the coordinate gradient, which coords
        # would otherwise require in learned-state mode (the k column carries the state's gradient)
        grid = grid.detach()
    if cache is not None:
        cache[key] = grid
    return grid


def rows_path(coords: torch.Tensor, channels: int) -> bool:
    """Whether planes are sampled as bags of rows (``rows_from_cells``): on a CPU without a graph (rendering,
    no-grad fields).

    Not for one-channel planes: embedding_bag's kernel for a one-column table rounds differently from
    grid_sample (widths 2-40, 48, 64, 96 and 128 all gave grid_sample's bits; the tests keep seven of them).
    """
    # a compiled field (train.compile) samples by grid_sample: dynamo refuses the rows' writes into strided slices
    return coords.device.type == "cpu" and channels > 1 and not torch.is_grad_enabled() \
        and not torch.compiler.is_compiling()


def axis_cells(values: torch.Tensor, size: int) -> torch.Tensor:
    """Coordinates in [-1, 1] along an axis of ``size`` vertices -> [3, *values.shape]: the cell's first vertex
    (a float), the weight of the vertex after it and the weight of the first one.

    grid_sample's arithmetic (align_corners, border clip; a NaN goes to the first vertex), so that a plane
    sampled from these cells gives its bits. Every plane of a level that reads the same axis at the same
    resolution shares one set (``KPlanesEncoding.forward_nc``).
    """
    x = ((values + 1) * ((size - 1) / 2)).nan_to_num_(0.0).clamp_(0, size - 1)
    cells = torch.empty(3, *values.shape, dtype=values.dtype, device=values.device)
    # a sample on the last vertex takes the cell before it with weight 1 on its far vertex: the same value
    torch.floor(x, out=cells[0]).clamp_(max=size - 1 - min(1, size - 1))
    torch.sub(x, cells[0], out=cells[1])
    torch.sub(1, cells[1], out=cells[2])  # grid_sample's (x0 + 1) - x, bit for bit
    return cells


def rows_from_cells(stack: torch.Tensor, cells: Sequence[tuple[torch.Tensor, torch.Tensor]]) -> torch.Tensor:
    """Plane ``g`` of ``stack`` [G, C, H, W] sampled at the cells ``(along W, along H)`` of ``cells[g]`` -> [G, N, C],
    for use without a gradient.

    grid_sample's CPU kernel loops over the channels and gathers one float per vertex and channel. Planes stored
    channels last hold a vertex's C features in one contiguous row, so a sample is a bag of four rows weighted
    by its bilinear weights: one ``embedding_bag`` (docs/model.md, "Rendering on a CPU"). With ``axis_cells``
    the arithmetic is grid_sample's (unnormalisation, border clip, weights, sum order), so the values are the
    same bits for C >= 2 (tested).
    """
    n_planes, channels, height, width = stack.shape
    rows = stack.permute(0, 2, 3, 1).reshape(-1, channels)  # a view for channels-last planes
    n = cells[0][0].shape[-1]
    dx, dy = min(1, width - 1), min(1, height - 1)
    # vertex numbers are exact in float32 below 2**24, and int32 indices halve the index traffic
    exact = rows.shape[0] < 2**24
    kind = torch.int32 if exact else torch.int64
    weights = torch.empty(n_planes, n, 4, dtype=stack.dtype, device=stack.device)
    first = torch.empty(n_planes, n, dtype=cells[0][0].dtype if exact else kind, device=stack.device)
    for g, (u, v) in enumerate(cells):
        # each product written into its slot of the sample's four (stack() and broadcast products are 2-6x slower)
        for slot, (a, b) in enumerate(((v[2], u[2]), (v[2], u[1]), (v[1], u[2]), (v[1], u[1]))):
            torch.mul(a, b, out=weights[g, :, slot])
        if exact:  # whole numbers below 2**24: every sum is exact
            torch.add(u[0], v[0], alpha=width, out=first[g])
        else:
            torch.add(u[0].to(kind), v[0].to(kind), alpha=width, out=first[g])
        if g:
            first[g].add_(g * height * width)
    # the four vertices' rows, each written into its slot (a broadcast add over [G, N, 4] took 3x as long)
    index = torch.empty(n_planes, n, 4, dtype=kind, device=stack.device)
    index[..., 0].copy_(first)
    for slot, corner in enumerate((dx, dy * width, dy * width + dx), start=1):
        torch.add(index[..., 0], corner, out=index[..., slot])
    out = F.embedding_bag(index.view(-1, 4), rows, per_sample_weights=weights.view(-1, 4), mode="sum")
    return out.view(n_planes, n, channels)


class KPlanesEncoding(nn.Module):
    """One scale of K-Planes: planes over ``pairs`` of an N-D coordinate, combined by product.

    Planes of the same shape and kind (spatial, or touching a non-spatial axis)
    are stored stacked in one parameter ``[G, C, H, W]`` and sampled by one
    ``grid_sample`` call: LiveScene's six planes per scale take two calls, not six.
    On a CPU without a graph (rendering, the no-grad fields of a step) one
    ``rows_from_cells`` call samples them instead, with the same values.

    Args:
        resolution: vertices per axis, one entry per input dimension.
        channels: feature channels of every plane.
        pairs: axis pairs that get a plane (default: all pairs).
        spatial_dims: axes ``< spatial_dims`` are spatial; planes touching any
            other axis are initialised to 1.
        init_range: uniform init of purely spatial planes.
    """

    def __init__(self, resolution: Sequence[int], channels: int, pairs: Sequence[tuple[int, int]] | None = None,
                 spatial_dims: int = 3, init_range: Sequence[float] = (0.1, 0.5)) -> None:
        super().__init__()
        self.resolution = [int(r) for r in resolution]
        self.n_dims = len(self.resolution)
        self.channels = int(channels)
        self.pairs = [tuple(p) for p in (pairs if pairs is not None else all_pairs(self.n_dims))]
        self.spatial_dims = spatial_dims
        groups: dict[tuple[int, int, bool], list[int]] = {}
        for i, (a, b) in enumerate(self.pairs):
            if not (0 <= a < self.n_dims and 0 <= b < self.n_dims and a != b):
                raise ValueError(f"plane pair {(a, b)} is not two distinct axes of a {self.n_dims}-D coordinate")
            # a plane is [C, res_b, res_a]: grid_sample reads the first coordinate along W (axis a), the second along H
            groups.setdefault((self.resolution[b], self.resolution[a], self.touches_non_spatial(a, b)), []).append(i)
        self.group_members = list(groups.values())
        # per group, fixed at construction: the pairs it holds and whether they are all spatial (read every forward)
        self._group_pairs = [[self.pairs[i] for i in members] for members in self.group_members]
        self._group_spatial = [not non_spatial for (_, _, non_spatial) in groups]
        self.slot = {i: (g, j) for g, members in enumerate(self.group_members) for j, i in enumerate(members)}
        self.plane_groups = nn.ParameterList()
        for (h, w, non_spatial), members in groups.items():
            stack = torch.empty(len(members), self.channels, h, w)
            if non_spatial:
                nn.init.ones_(stack)
            else:
                nn.init.uniform_(stack, float(init_range[0]), float(init_range[1]))
            # channels last: a sample's C features of one vertex share a cache line (grid_sample ~30% faster on
            # the CPU for the large planes)
            self.plane_groups.append(nn.Parameter(stack.contiguous(memory_format=torch.channels_last)))

    def touches_non_spatial(self, a: int, b: int) -> bool:
        return a >= self.spatial_dims or b >= self.spatial_dims

    def group_pairs(self, g: int) -> list[tuple[int, int]]:
        return self._group_pairs[g]

    def group_is_spatial(self, g: int) -> bool:
        return self._group_spatial[g]

    @property
    def planes(self) -> list[torch.Tensor]:
        """Every plane as a ``[1, C, H, W]`` view of its group, in ``pairs`` order (in-place edits reach the group)."""
        return [self.plane_groups[g][j : j + 1] for g, j in (self.slot[i] for i in range(len(self.pairs)))]

    @property
    def k_plane_indices(self) -> list[int]:
        """Indices of planes that involve a non-spatial axis (k, time, states)."""
        return [i for i, (a, b) in enumerate(self.pairs) if self.touches_non_spatial(a, b)]

    @property
    def out_dim(self) -> int:
        return self.channels

    def _product(self, sample: Callable[[int, torch.Tensor], torch.Tensor], in_place: bool) -> torch.Tensor:
        """The product over every plane of ``sample(g, stack)``'s per-plane features of group ``g``, in its layout."""
        out: torch.Tensor | None = None
        for g, stack in enumerate(self.plane_groups):
            # products by hand: prod()'s backward looks for zeros (a host sync). unbind, not f[j]: the backward
            # of each f[j] zero-fills a gradient of all of f and adds it into f's, unbind's stacks the slices once
            for plane in sample(g, stack).unbind(0):
                if out is None:
                    out = plane
                elif in_place:
                    out.mul_(plane)
                else:
                    out = out * plane
        assert out is not None
        return out

    def forward_cn(self, coords: torch.Tensor, cache: PlaneGrids | None = None) -> torch.Tensor:
        """``coords`` [N, n_dims] in [-1, 1] -> features [C, N] (grid_sample's layout)."""
        def sample(g: int, stack: torch.Tensor) -> torch.Tensor:
            grid = plane_grid(coords, self.group_pairs(g), self.group_is_spatial(g), cache).to(stack.dtype)
            return F.grid_sample(stack, grid, mode="bilinear", padding_mode="border", align_corners=True).squeeze(-1)

        return self._product(sample, in_place=False)

    def forward_nc(self, coords: torch.Tensor, cache: PlaneGrids | None = None) -> torch.Tensor:
        """``coords`` [N, n_dims] in [-1, 1] -> features [N, C], sampled as bags of vertex rows (no gradient).

        Each axis is cut into cells once per resolution (``axis_cells``) for every plane, field and scale that
        reads it at that resolution: a level's probability tri-plane and first radiance scale share theirs.
        """
        cache = {} if cache is None else cache

        def cells(axis: int, size: int, dtype: torch.dtype) -> torch.Tensor:
            key = ("cells", axis, size)
            if key not in cache:
                cache[key] = axis_cells(coords[:, axis].to(dtype), size)
            return cache[key]

        def sample(g: int, stack: torch.Tensor) -> torch.Tensor:
            height, width = stack.shape[-2:]
            return rows_from_cells(stack, [(cells(a, width, stack.dtype), cells(b, height, stack.dtype))
                                           for a, b in self.group_pairs(g)])

        # the products are new arrays (no graph to keep): multiplied in place
        return self._product(sample, in_place=True)

    def forward(self, coords: torch.Tensor, cache: PlaneGrids | None = None) -> torch.Tensor:
        """``coords`` [N, n_dims] in [-1, 1] -> features [N, C]."""
        if rows_path(coords, self.channels):
            return self.forward_nc(coords, cache)
        return self.forward_cn(coords, cache).transpose(0, 1)


class MultiScaleKPlanes(nn.Module):
    """K-Planes at several spatial scales; non-spatial axes keep their resolution. Features concatenated."""

    def __init__(self, base_resolution: Sequence[int], channels: int, scales: Sequence[int] = (1,),
                 pairs: Sequence[tuple[int, int]] | None = None, spatial_dims: int = 3,
                 init_range: Sequence[float] = (0.1, 0.5)) -> None:
        super().__init__()
        self.grids = nn.ModuleList()
        for s in scales:
            res = [int(r) * int(s) if i < spatial_dims else int(r) for i, r in enumerate(base_resolution)]
            self.grids.append(KPlanesEncoding(res, channels, pairs, spatial_dims, init_range))

    @property
    def out_dim(self) -> int:
        return sum(g.out_dim for g in self.grids)

    def forward(self, coords: torch.Tensor, cache: PlaneGrids | None = None) -> torch.Tensor:
        # every scale samples the same pairs at the same points: one grid per pair group serves them all
        cache = {} if cache is None else cache
        if rows_path(coords, self.grids[0].channels):
            return torch.cat([g.forward_nc(coords, cache) for g in self.grids], dim=1)
        return torch.cat([g.forward_cn(coords, cache) for g in self.grids], dim=0).transpose(0, 1)


class SHEncoding(nn.Module):
    """Real spherical harmonics of unit directions up to ``degree`` (4 -> 16 components)."""

    def __init__(self, degree: int = 4) -> None:
        super().__init__()
        if not 1 <= degree <= 4:
            raise ValueError(f"SH degree must be 1..4, got {degree}")
        self.degree = degree

    @property
    def out_dim(self) -> int:
        return self.degree**2

    def forward(self, directions: torch.Tensor) -> torch.Tensor:
        """``directions`` [N, 3] (unit) -> [N, degree**2]."""
        x, y, z = directions.unbind(-1)
        out = [torch.full_like(x, 0.28209479177387814)]
        if self.degree > 1:
            out += [-0.48860251190291987 * y, 0.48860251190291987 * z, -0.48860251190291987 * x]
        if self.degree > 2:
            xx, yy, zz = x * x, y * y, z * z
            out += [1.0925484305920792 * x * y, -1.0925484305920792 * y * z,
                    0.94617469575755997 * zz - 0.31539156525251999,
                    -1.0925484305920792 * x * z, 0.54627421529603959 * (xx - yy)]
        if self.degree > 3:
            out += [0.59004358992664352 * y * (-3.0 * xx + yy), 2.8906114426405538 * x * y * z,
                    0.45704579946446572 * y * (1.0 - 5.0 * zz), 0.3731763325901154 * z * (5.0 * zz - 3.0),
                    0.45704579946446572 * x * (1.0 - 5.0 * zz), 1.4453057213202769 * z * (xx - yy),
                    0.59004358992664352 * x * (-xx + 3.0 * yy)]
        return torch.stack(out, dim=-1)


class Grid1DEncoding(nn.Module):
    """A learnable 1D grid of ``resolution + 1`` vertices over [0, 1], linearly interpolated."""

    def __init__(self, resolution: int, channels: int, init_range: Sequence[float] = (0.0, 1.0)) -> None:
        super().__init__()
        self.resolution = int(resolution)
        self.values = nn.Parameter(torch.empty(self.resolution + 1, channels))
        nn.init.uniform_(self.values, float(init_range[0]), float(init_range[1]))

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        """``t`` [N] in [0, 1] -> [N, channels]."""
        pos = t.clamp(0.0, 1.0) * self.resolution
        lo = pos.floor().clamp(max=self.resolution - 1).long()
        frac = (pos - lo.to(pos.dtype)).unsqueeze(-1)
        return self.values[lo] * (1.0 - frac) + self.values[lo + 1] * frac


def sinusoidal_encoding(t: torch.Tensor, channels: int, scale: float = 2 * math.pi,
                        base: float = 1000.0) -> torch.Tensor:
    """Transformer-style sin/cos of ``t`` [N] -> [N, channels] (channels even), frequencies base^(-2i/channels)."""
    half = torch.arange(0, channels, 2, device=t.device, dtype=torch.float32)
    freq = torch.exp(half * (-math.log(base) / channels))
    arg = t.float().unsqueeze(-1) * scale * freq
    out = torch.zeros(*t.shape, channels, device=t.device, dtype=torch.float32)
    out[..., 0::2] = torch.sin(arg)
    out[..., 1::2] = torch.cos(arg)
    return out
