"""Every loss term of docs/method.md section 5, each a small function; weights live in ``LossWeights``.

Regularisers on K-Planes follow the K-Planes paper: total variation of the
planes (for planes with a k axis only along their spatial axis), L1 of the k
planes to 1 (a static scene needs no k), and second-difference smoothness
along k.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from .encodings import KPlanesEncoding, MultiScaleKPlanes
from .ray_samplers import RaySamples


def rgb_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    return F.mse_loss(pred.float(), target.float())


def _outer_envelope(t0: torch.Tensor, t1: torch.Tensor, y1: torch.Tensor) -> torch.Tensor:
    """Mass of the histogram (edges t1 [R, S1 + 1], masses y1 [R, S1]) over each interval of t0 [R, S0 + 1]."""
    cy1 = torch.cat([torch.zeros_like(y1[:, :1]), torch.cumsum(y1, dim=-1)], dim=-1)
    last = y1.shape[-1] - 1
    idx_lo = (torch.searchsorted(t1[:, :-1].contiguous(), t0[:, :-1].contiguous(), side="right") - 1).clamp(0, last)
    idx_hi = torch.searchsorted(t1[:, 1:].contiguous(), t0[:, 1:].contiguous(), side="right").clamp(0, last)
    return torch.gather(cy1[:, 1:], 1, idx_hi) - torch.gather(cy1[:, :-1], 1, idx_lo)


def interlevel_loss(proposal: list[tuple[RaySamples, torch.Tensor]],
                    final: tuple[RaySamples, torch.Tensor]) -> torch.Tensor:
    """Mip-NeRF 360 proposal loss: proposal weights must bound the (detached) final weights from above."""
    samples, weights = final
    c, w = samples.bins.detach(), weights.detach().float()
    total = torch.zeros((), device=w.device)
    for ps, pw in proposal:
        envelope = _outer_envelope(c, ps.bins.detach(), pw.float())
        total = total + (torch.clamp(w - envelope, min=0.0) ** 2 / (w + 1.1920929e-07)).mean()
    return total


def distortion_loss(samples: RaySamples, weights: torch.Tensor, nears: torch.Tensor,
                    fars: torch.Tensor) -> torch.Tensor:
    """Mip-NeRF 360 distortion on normalised ray distance, in O(S) with cumulative sums."""
    span = (fars - nears).clamp(min=1e-6)[:, None]
    s = (samples.bins - nears[:, None]) / span
    mids = 0.5 * (s[:, 1:] + s[:, :-1])
    widths = s[:, 1:] - s[:, :-1]
    w = weights.float()
    # sum_{i,j} w_i w_j |m_i - m_j| = 2 sum_i w_i (m_i W_<i - (wm)_<i) for sorted m
    w_before = torch.cumsum(w, dim=-1) - w
    wm_before = torch.cumsum(w * mids, dim=-1) - w * mids
    inter = 2.0 * (w * (mids * w_before - wm_before)).sum(dim=-1)
    intra = (w**2 * widths).sum(dim=-1) / 3.0
    return (inter + intra).mean()


def _grids(encoding: KPlanesEncoding | MultiScaleKPlanes) -> list[KPlanesEncoding]:
    return list(encoding.grids) if isinstance(encoding, MultiScaleKPlanes) else [encoding]


def _zero(encoding: KPlanesEncoding | MultiScaleKPlanes) -> torch.Tensor:
    """A 0 on the encoding's device and dtype, for a term with nothing to sum."""
    param = next(encoding.parameters(), None)
    return param.new_zeros(()) if param is not None else torch.zeros(())


def _stacks(encoding: KPlanesEncoding | MultiScaleKPlanes, k_only: bool = False) -> list[tuple[torch.Tensor, bool]]:
    """Every stacked plane group ``[G, C, H, W]`` with whether it touches a non-spatial axis.

    Regularisers work on whole stacks (one op for G planes, and no slice of a
    stack whose backward would write a full-size zero gradient per plane).
    """
    return [(stack, not grid.group_is_spatial(g)) for grid in _grids(encoding)
            for g, stack in enumerate(grid.plane_groups) if not k_only or not grid.group_is_spatial(g)]


class _NeighbourSquares(torch.autograd.Function):
    """Per plane of a stack [G, C, H, W]: mean squared difference of neighbours along ``dim`` -> [G].

    Its gradient is written directly (``2 / n * (d[k - 1] - d[k])``): autograd's version runs the two
    slices' backward, each a full-size zero tensor, and this term ran every step over every plane.
    """

    @staticmethod
    def forward(ctx, stack: torch.Tensor, dim: int) -> torch.Tensor:  # type: ignore[override]
        d = torch.diff(stack, dim=dim)
        ctx.save_for_backward(d)
        ctx.dim, ctx.n = dim, d[0].numel()
        return d.square().mean(dim=(1, 2, 3))

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, None]:  # type: ignore[override]
        (d,) = ctx.saved_tensors
        gd = d * (grad.view(-1, 1, 1, 1) * (2.0 / ctx.n))
        # vertex k gets -(gd[k] - gd[k - 1]) (gd zero beyond either end): a padded copy's diff written in place, with
        # its arithmetic, so the same bits, zeros' signs included (gd[k - 1] - gd[k] flips them, and that changed a
        # CoNeRF-style run after 60 steps); in the planes' layout, so it adds into their gradient without a copy
        dim, m = ctx.dim, gd.shape[ctx.dim]  # m differences between m + 1 vertices
        shape = (*gd.shape[:dim], m + 1, *gd.shape[dim + 1 :])
        layout = torch.channels_last if gd.is_contiguous(memory_format=torch.channels_last) else torch.contiguous_format
        out = torch.empty(shape, dtype=gd.dtype, device=gd.device, memory_format=layout)
        out.narrow(dim, 0, 1).copy_(gd.narrow(dim, 0, 1))
        torch.sub(gd.narrow(dim, 1, m - 1), gd.narrow(dim, 0, m - 1), out=out.narrow(dim, 1, m - 1))
        torch.sub(0.0, gd.narrow(dim, m - 1, 1), out=out.narrow(dim, m, 1))
        return out.neg_(), None


def plane_tv(encoding: KPlanesEncoding | MultiScaleKPlanes) -> torch.Tensor:
    """Mean over every plane of its mean squared neighbour difference; k planes only along their spatial axis (W)."""
    per_plane = []
    for stack, touches_k in _stacks(encoding):
        # a k plane (a, k) stores the spatial axis a along W, k along H
        tv = _NeighbourSquares.apply(stack, 3)
        if not touches_k:
            tv = tv + _NeighbourSquares.apply(stack, 2)
        per_plane.append(tv)
    return torch.cat(per_plane).mean() if per_plane else _zero(encoding)


def k_planes_l1(encoding: KPlanesEncoding | MultiScaleKPlanes) -> torch.Tensor:
    """Mean |1 - plane| over the planes with a k axis (0 when the field ignores k)."""
    terms = [(1.0 - stack).abs().mean(dim=(1, 2, 3)) for stack, _ in _stacks(encoding, k_only=True)]
    return torch.cat(terms).mean() if terms else _zero(encoding)


def k_smoothness(encoding: KPlanesEncoding | MultiScaleKPlanes) -> torch.Tensor:
    """Mean squared second difference along the k axis (H) of the k planes."""
    terms = [(p[..., 2:, :] - 2 * p[..., 1:-1, :] + p[..., :-2, :]).square().mean(dim=(1, 2, 3))
             for p, _ in _stacks(encoding, k_only=True) if p.shape[-2] >= 3]
    return torch.cat(terms).mean() if terms else _zero(encoding)


def _masked_mean(values: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of ``values`` where ``mask``; 0 (with gradient 0) where nothing is selected.

    Written with a multiply instead of boolean indexing so no host sync is needed
    to learn how many entries there are (a training step never waits on the GPU).
    """
    m = mask.to(values.dtype)
    return (values * m).sum() / m.sum().clamp(min=1.0)


def focal_mask_loss(rendered_logits: torch.Tensor, labels: torch.Tensor, gamma: float = 1.5) -> torch.Tensor:
    """``0.5 * (1 - exp(-CE))^gamma * CE`` of rendered logits [R, C] vs labels [R] (-1 = no label, skipped)."""
    valid = labels >= 0
    ce = F.cross_entropy(rendered_logits.float(), labels.clamp(min=0), reduction="none")
    return _masked_mean(_focal(ce, gamma), valid)


def _focal(ce: torch.Tensor, gamma: float, p_label: torch.Tensor | None = None) -> torch.Tensor:
    """``0.5 * (1 - p)^gamma * CE`` with ``p = exp(-CE)`` unless the label's probability is given."""
    p = torch.exp(-ce) if p_label is None else p_label
    return 0.5 * (1.0 - p) ** gamma * ce


def focal_mask_loss_probs(rendered_probs: torch.Tensor, labels: torch.Tensor, gamma: float = 1.5) -> torch.Tensor:
    """The focal mask loss of rendered probabilities [R, C] (weights times per-sample softmax, summed along the ray).

    The rendered sum is divided by the ray's total weight, so a ray that leaves the box half transparent is
    judged by the samples it has; CE is ``-log`` of the label's share, floored to keep it finite.
    """
    valid = labels >= 0
    p = rendered_probs.float()
    p = p / p.sum(dim=-1, keepdim=True).clamp(min=1e-6)
    p_label = p.gather(1, labels.clamp(min=0)[:, None])[:, 0].clamp(min=1e-6)
    ce = -torch.log(p_label)
    return _masked_mean(_focal(ce, gamma, p_label), valid)


def focal_mask_loss_samples(weights: torch.Tensor, logits: torch.Tensor, labels: torch.Tensor,
                            gamma: float = 1.5) -> torch.Tensor:
    """Every sample's focal CE against its ray's label, weighted by the (detached) rendering weights [R, S].

    ``logits`` [R, S, C]. Per ray the weighted sum is divided by the ray's total weight. Unlike the rendered
    forms, a sample that carries weight cannot hide behind another sample's extreme logit, and a confidently
    wrong sample still gets a gradient.
    """
    valid = labels >= 0
    n_rays, n_samples, n_classes = logits.shape
    target = labels.clamp(min=0)[:, None].expand(n_rays, n_samples).reshape(-1)
    ce = F.cross_entropy(logits.reshape(-1, n_classes).float(), target, reduction="none")
    focal = _focal(ce, gamma).view(n_rays, n_samples)
    w = weights.detach().float()
    per_ray = (w * focal).sum(-1) / w.sum(-1).clamp(min=1e-6)
    return _masked_mean(per_ray, valid)


def repulsion_loss(rendered_logits: torch.Tensor, labels: torch.Tensor, margin: float = 10.0) -> torch.Tensor:
    """``ELU(K - d) + 1`` with ``d`` the mean L1 distance of the rendered logits of ray pairs with different labels.

    Pairs are (first half, second half) of a randomly drawn batch. As in the
    reference code, ``d`` is ONE mean over all differing pairs, taken over the
    two logit channels where their one-hot labels differ (each pair's own
    label channels), and the hinge applies to that mean: the term pushes the
    classes apart on average instead of forcing every pair past ``K``. A batch
    without a differing pair gives 0.
    """
    half = rendered_logits.shape[0] // 2
    a, b = rendered_logits[:half].float(), rendered_logits[half : 2 * half].float()
    la, lb = labels[:half], labels[half : 2 * half]
    differ = (la != lb) & (la >= 0) & (lb >= 0)
    ia, ib = la.clamp(min=0)[:, None], lb.clamp(min=0)[:, None]
    pair = (a.gather(1, ia) - b.gather(1, ia)).abs()[:, 0] + (a.gather(1, ib) - b.gather(1, ib)).abs()[:, 0]
    dist = _masked_mean(pair, differ) / 2.0  # the mean over both channels of every differing pair
    return torch.where(differ.any(), F.elu(margin - dist) + 1.0, torch.zeros_like(dist))


def language_loss(rendered: torch.Tensor, target: torch.Tensor, valid: torch.Tensor,
                  delta: float = 1.25) -> torch.Tensor:
    """Huber loss of rendered embeddings [R, D] vs targets [R, D] on rays with a label."""
    per_ray = F.huber_loss(rendered.float(), target.float(), delta=delta, reduction="none").sum(-1)
    return _masked_mean(per_ray, valid)


def state_loss(predicted: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """MSE of learned states vs key-frame values; NaN targets (object not annotated) are skipped."""
    valid = torch.isfinite(target)
    # the NaN targets are replaced before the difference, so their zero weight cannot meet a NaN gradient
    diff = predicted - torch.where(valid, target, predicted.detach())
    return _masked_mean(diff.square(), valid)
