"""Each loss term is zero (or minimal) exactly where it should be, and positive otherwise."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from stages.model import losses as L
from stages.model.encodings import KPlanesEncoding, MultiScaleKPlanes
from stages.model.ray_samplers import RaySamples, pdf_samples, uniform_samples


def test_rgb_loss():
    x = torch.rand(10, 3)
    assert L.rgb_loss(x, x).item() == 0
    assert L.rgb_loss(x, x + 0.1).item() == pytest.approx(0.01, rel=1e-4)


def test_interlevel_zero_when_proposal_bounds_final_weights():
    bins = torch.linspace(0, 1, 9).expand(4, 9)
    s = RaySamples(bins)
    w = torch.softmax(torch.randn(4, 8), -1)
    assert L.interlevel_loss([(s, w)], (s, w)).item() == pytest.approx(0.0, abs=1e-7)
    assert L.interlevel_loss([(s, w * 2)], (s, w)).item() == pytest.approx(0.0, abs=1e-7)
    assert L.interlevel_loss([(s, w * 0.5)], (s, w)).item() > 1e-3
    # a coarse proposal whose single bin holds all the mass bounds any final histogram inside it
    coarse = RaySamples(torch.tensor([[0.0, 1.0]]).expand(4, 2))
    assert L.interlevel_loss([(coarse, torch.ones(4, 1))], (s, w)).item() == pytest.approx(0.0, abs=1e-7)


def test_distortion_minimal_for_a_concentrated_ray():
    bins = torch.linspace(0, 1, 33)[None]
    nears, fars = torch.zeros(1), torch.ones(1)
    spike = torch.zeros(1, 32)
    spike[0, 10] = 1.0
    spread = torch.full((1, 32), 1 / 32)
    d_spike = L.distortion_loss(RaySamples(bins), spike, nears, fars).item()
    d_spread = L.distortion_loss(RaySamples(bins), spread, nears, fars).item()
    assert d_spike == pytest.approx((1 / 32) / 3, rel=1e-5)  # only the intra-interval term remains
    assert d_spread > 5 * d_spike
    # the O(S) form equals the quadratic definition
    w = torch.rand(3, 32)
    m = 0.5 * (bins[:, 1:] + bins[:, :-1])
    quad = (w[:, :, None] * w[:, None, :] * (m[:, :, None] - m[:, None, :]).abs()).sum((1, 2))
    quad = quad + (w**2 * (bins[:, 1:] - bins[:, :-1])).sum(-1) / 3
    fast = L.distortion_loss(RaySamples(bins.expand(3, 33)), w, torch.zeros(3), torch.ones(3))
    assert fast.item() == pytest.approx(quad.mean().item(), rel=1e-5)


def test_plane_regularisers_zero_on_flat_planes_positive_otherwise():
    enc = MultiScaleKPlanes([6, 6, 6, 5], channels=2, scales=[1, 2])
    assert L.k_planes_l1(enc).item() == 0  # fresh k planes are exactly 1
    assert L.k_smoothness(enc).item() == 0
    assert L.plane_tv(enc).item() > 0  # random spatial planes
    with torch.no_grad():
        for g in enc.grids:
            for p in g.planes:
                p.fill_(0.3)
    assert L.plane_tv(enc).item() == 0
    assert L.k_planes_l1(enc).item() == pytest.approx(0.7)
    # a k plane that is linear along k has no second difference, but TV along its spatial axis counts
    g = KPlanesEncoding([4, 4, 4, 5], 1)
    with torch.no_grad():
        g.planes[2].copy_(torch.linspace(0, 1, 5).view(1, 1, 5, 1).expand(1, 1, 5, 4))
    assert L.k_smoothness(g).item() == pytest.approx(0.0, abs=1e-12)
    tv_before = L.plane_tv(g).item()
    with torch.no_grad():
        g.planes[2][..., 0] += 1.0  # a jump along x
    assert L.plane_tv(g).item() > tv_before


def test_focal_mask_loss():
    labels = torch.tensor([0, 2, 1, -1])
    sure = torch.full((4, 3), -20.0)
    sure[torch.arange(3), labels[:3]] = 20.0
    assert L.focal_mask_loss(sure, labels).item() == pytest.approx(0.0, abs=1e-12)
    wrong = sure.roll(1, dims=1)
    assert L.focal_mask_loss(wrong, labels).item() > 10
    # the focal factor: with CE = c, loss = 0.5 (1 - e^-c)^1.5 c
    uniform = torch.zeros(1, 3)
    ce = torch.log(torch.tensor(3.0))
    expect = 0.5 * (1 - torch.exp(-ce)) ** 1.5 * ce
    assert L.focal_mask_loss(uniform, torch.tensor([1])).item() == pytest.approx(expect.item(), rel=1e-5)
    assert L.focal_mask_loss(uniform, torch.tensor([-1])).item() == 0  # unlabelled rays are skipped


def test_focal_mask_loss_on_probabilities():
    # one sample of weight 1 per ray: rendered probabilities are the sample's softmax, and the loss is the focal form.
    # Seeded, and the logits kept within +-6 so a label's probability is at least e^-12 / 4 > 1e-6: the probability
    # form floors it at 1e-6 (CE at most 13.8), and a label logit 13.8 below the row's maximum would make the two
    # forms differ by that floor, not by a defect
    g = torch.Generator().manual_seed(0)
    logits = (torch.rand(6, 4, generator=g) * 2 - 1) * 6
    labels = torch.tensor([0, 1, 2, 3, 1, -1])
    probs = torch.softmax(logits, -1)
    assert L.focal_mask_loss_probs(probs, labels).item() == pytest.approx(
        L.focal_mask_loss(logits, labels).item(), rel=1e-5)
    # judged by the ray's own weight: half-transparent rays count as their samples say
    assert L.focal_mask_loss_probs(0.5 * probs, labels).item() == pytest.approx(
        L.focal_mask_loss_probs(probs, labels).item(), rel=1e-5)
    assert L.focal_mask_loss_probs(probs, torch.full((6,), -1)).item() == 0  # unlabelled rays are skipped
    # the failure the option exists for: the surface (weight 0.9) is class 0, a floater (weight 0.06) has an extreme
    # logit against class 0; the rendered logits call the ray class 1 and their loss for label 1 is small, while
    # the rendered probabilities say the weight-carrying samples are class 0
    sample_logits = torch.tensor([[[6.0, 2.0, 0.0], [-60.0, 10.0, 0.0]]])
    weights = torch.tensor([[0.9, 0.06]])
    rendered_logits = (weights[..., None] * sample_logits).sum(1)
    rendered_probs = (weights[..., None] * torch.softmax(sample_logits, -1)).sum(1)
    label1 = torch.tensor([1])
    assert rendered_logits.argmax(-1).item() == 1 and L.focal_mask_loss(rendered_logits, label1).item() < 0.1
    assert L.focal_mask_loss_probs(rendered_probs, label1).item() > 1.0


def test_focal_mask_loss_on_samples():
    # one sample per ray: the per-sample form is the focal loss of that sample's logits
    logits = torch.randn(6, 1, 4) * 3
    labels = torch.tensor([0, 1, 2, 3, 1, -1])
    ones = torch.ones(6, 1)
    assert L.focal_mask_loss_samples(ones, logits, labels).item() == pytest.approx(
        L.focal_mask_loss(logits[:, 0], labels).item(), rel=1e-5)
    # the floater case of test_focal_mask_loss_on_probabilities: the surface sample of class 0 carries the weight, so
    # label 1 costs what the surface's own CE costs, however extreme the floater's logit
    sample_logits = torch.tensor([[[6.0, 2.0, 0.0], [-60.0, 10.0, 0.0]]])
    weights = torch.tensor([[0.9, 0.06]])
    surface = L.focal_mask_loss(sample_logits[:, 0], torch.tensor([1])).item()
    got = L.focal_mask_loss_samples(weights, sample_logits, torch.tensor([1])).item()
    assert got == pytest.approx((0.9 * surface + 0.06 * 0.0) / 0.96, rel=1e-3) and got > 1.0
    # a confidently wrong sample still has a gradient (the rendered-probability form's vanishes)
    lg = torch.tensor([[[30.0, -30.0, 0.0]]], requires_grad=True)
    L.focal_mask_loss_samples(torch.ones(1, 1), lg, torch.tensor([1])).backward()
    assert lg.grad.abs().sum() > 0.1


def test_repulsion_loss():
    labels = torch.tensor([0, 1, 1, 1])  # pairs (0, 1, differ) and (1, 1, same)
    far = torch.tensor([[30.0, 0.0], [0.0, 0.0], [0.0, 30.0], [0.0, 0.0]])  # differ by 30 in both label channels
    assert L.repulsion_loss(far, labels, margin=10).item() == pytest.approx(0.0, abs=1e-6)
    near = torch.zeros(4, 2)
    assert L.repulsion_loss(near, labels, margin=10).item() == pytest.approx(11.0)  # ELU(10) + 1
    assert L.repulsion_loss(near, torch.tensor([1, 0, 1, 0]), margin=10).item() == 0  # no differing pair
    # only the pair's own label channels count: a gap of 4 in channels 0 and 1, a huge one in channel 2
    three = torch.tensor([[4.0, 0.0, 100.0], [0.0, 0.0, 0.0], [0.0, 4.0, 0.0], [0.0, 0.0, 0.0]])
    assert L.repulsion_loss(three, labels, margin=10).item() == pytest.approx(7.0)  # ELU(10 - 4) + 1


def test_language_and_state_losses():
    x = torch.nn.functional.normalize(torch.randn(6, 8), dim=-1)
    valid = torch.tensor([True, True, False, True, True, True])
    assert L.language_loss(x, x, valid).item() == 0
    assert L.language_loss(x, -x, valid).item() > 0
    target = torch.tensor([[0.2, float("nan")], [0.9, 0.1]])
    pred = torch.tensor([[0.2, 0.7], [0.9, 0.1]])
    assert L.state_loss(pred, target).item() == 0
    assert L.state_loss(pred + 0.1, target).item() == pytest.approx(0.01, rel=1e-5)


def test_samplers_bins_sorted_inside_ray_and_pdf_follows_weights():
    nears, fars = torch.tensor([0.5, 1.0]), torch.tensor([2.0, 3.0])
    g = torch.Generator().manual_seed(0)
    s = uniform_samples(nears, fars, 16, jitter=True, generator=g)
    assert torch.all(s.deltas >= 0)
    assert torch.all(s.bins >= nears[:, None]) and torch.all(s.bins <= fars[:, None])
    w = torch.zeros(2, 16)
    w[:, 5] = 1.0
    fine = pdf_samples(s, w, 32, jitter=False, padding=0.0)
    inside = (fine.mids >= s.bins[:, 5:6]) & (fine.mids <= s.bins[:, 6:7])
    assert inside.float().mean() > 0.9


def test_k_regularisers_of_a_field_without_k_planes_follow_its_dtype():
    """A spatial-only field (no k axis) gives a 0 on the field's own device and dtype, not a CPU float32."""
    enc = KPlanesEncoding([4, 4, 4], 2).to(torch.float64)
    for term in (L.k_planes_l1(enc), L.k_smoothness(enc)):
        assert term.item() == 0 and term.dtype == torch.float64 and term.device == enc.planes[0].device


def test_plane_tv_gradient_written_by_hand_matches_autograd():
    from stages.model.losses import _NeighbourSquares

    for shape in ((3, 2, 5, 7), (2, 3, 2, 2)):  # two vertices: one difference, no interior vertex
        x = torch.rand(*shape, dtype=torch.float64).contiguous(memory_format=torch.channels_last).requires_grad_(True)
        for dim in (2, 3):
            assert torch.autograd.gradcheck(lambda t, d=dim: _NeighbourSquares.apply(t, d), (x,))
            n = x.shape[dim] - 1
            plain = (x.narrow(dim, 1, n) - x.narrow(dim, 0, n)).square().mean(dim=(1, 2, 3))
            torch.testing.assert_close(_NeighbourSquares.apply(x, dim), plain)
            # the gradient comes in the planes' channels-last layout (accumulated into theirs without a copy)
            (grad,) = torch.autograd.grad(_NeighbourSquares.apply(x, dim).sum(), x)
            assert grad.is_contiguous(memory_format=torch.channels_last)
    # bit for bit the padded diff's gradient, the signs of zeros too (equal neighbours give zero differences)
    x = torch.rand(2, 3, 6, 6).round().contiguous(memory_format=torch.channels_last).requires_grad_(True)
    for dim in (2, 3):
        d = torch.diff(x.detach(), dim=dim)
        gd = d * (torch.ones(2).view(-1, 1, 1, 1) * (2.0 / d[0].numel()))
        expected = -torch.diff(F.pad(gd, (1, 1) if dim == 3 else (0, 0, 1, 1)), dim=dim)
        (grad,) = torch.autograd.grad(_NeighbourSquares.apply(x, dim).sum(), x)
        assert torch.equal(grad.contiguous().view(torch.int32), expected.contiguous().view(torch.int32))


def test_repulsion_ignores_pairs_with_an_unlabelled_ray():
    # pairs (ray 0, ray 2) = labels (0, 1), which differ, and (ray 1, ray 3) = (-1, 1), which has no label to compare
    labels = torch.tensor([0, -1, 1, 1])
    logits = torch.tensor([[12.0, 0.0], [0.0, 0.0], [0.0, 12.0], [0.0, 0.0]])
    # only the first pair counts: a gap of 12 in each of its label channels, d = 12, ELU(10 - 12) + 1 = e^-2
    assert L.repulsion_loss(logits, labels, margin=10).item() == pytest.approx(torch.exp(torch.tensor(-2.0)).item(),
                                                                              rel=1e-6)
    # no pair with both rays labelled: nothing to repel, exactly 0
    assert L.repulsion_loss(logits, torch.tensor([-1, -1, 0, 1]), margin=10).item() == 0


def test_language_loss_is_the_huber_loss_summed_over_the_embedding():
    # Huber per element: d^2 / 2 for |d| <= delta, delta (|d| - delta / 2) beyond; summed over D per ray
    rendered = torch.zeros(1, 4)
    target = torch.tensor([[1.0, 0.0, 0.0, 2.0]])
    valid = torch.tensor([True])
    assert L.language_loss(rendered, target, valid, delta=1.25).item() == pytest.approx(
        0.5 + 1.25 * (2.0 - 0.625), rel=1e-6)  # 2.21875
    assert L.language_loss(rendered, target, valid, delta=1.0).item() == pytest.approx(0.5 + 1.0 * 1.5, rel=1e-6)
    # the mean over the labelled rays only: an unlabelled ray with a large error changes nothing
    two = torch.cat([rendered, torch.full((1, 4), 9.0)])
    both = torch.cat([target, torch.zeros(1, 4)])
    got = L.language_loss(two, both, torch.tensor([True, False]), delta=1.25).item()
    assert got == pytest.approx(2.21875, rel=1e-6)


def test_state_loss_gradient_reaches_the_predicted_states():
    # mean over the finite targets of (p - t)^2: d/dp = 2 (p - t) / 3 at the three valid entries, 0 at the NaN one
    pred = torch.tensor([[0.3, 0.7], [1.0, 0.2]], requires_grad=True)
    target = torch.tensor([[0.2, float("nan")], [0.9, 0.1]])
    loss = L.state_loss(pred, target)
    assert loss.item() == pytest.approx(0.01, rel=1e-5)
    loss.backward()
    g = 2 * 0.1 / 3
    torch.testing.assert_close(pred.grad, torch.tensor([[g, 0.0], [g, g]]))


def test_interlevel_loss_stops_the_gradient_at_the_final_weights():
    """Mip-NeRF 360: the proposal bounds the final weights, which are not pulled down to meet it."""
    s = RaySamples(torch.linspace(0, 1, 5).expand(2, 5))
    final = torch.tensor([[0.1, 0.4, 0.3, 0.2], [0.25, 0.25, 0.25, 0.25]], requires_grad=True)
    proposal = (0.5 * final.detach()).requires_grad_(True)  # below the final weights everywhere: a positive loss
    loss = L.interlevel_loss([(s, proposal)], (s, final))
    assert loss.item() > 0
    loss.backward()
    assert final.grad is None
    assert proposal.grad is not None and proposal.grad.sum() < 0  # raising the proposal lowers the loss


def test_interlevel_envelope_starts_at_the_bin_that_holds_the_interval_start():
    # final and proposal share the edges [0, 0.5, 1]; the final mass is in [0.5, 1], the proposal's in [0, 0.5]. The
    # proposal's [0, 0.5] ends where [0.5, 1] starts, so it is not part of the envelope over [0.5, 1] (Mip-NeRF 360's
    # searchsorted: the lower end is the last edge <= the interval's start). The envelope there is 0 and the bound is
    # violated by 1: (1 - 0)^2 / (1 + eps), averaged with interval 0's 0, is 0.5
    s = RaySamples(torch.tensor([[0.0, 0.5, 1.0]]))
    final = torch.tensor([[0.0, 1.0]])
    proposal = torch.tensor([[1.0, 0.0]])
    assert L.interlevel_loss([(s, proposal)], (s, final)).item() == pytest.approx(0.5, rel=1e-6)


def test_distortion_is_measured_on_normalised_distance():
    # the spike of test_distortion_minimal_for_a_concentrated_ray on a ray from 1 to 3: normalised, its bins are the
    # same 32 equal intervals of [0, 1], so the loss is the same (1 / 32) / 3
    bins = torch.linspace(1, 3, 33)[None]
    spike = torch.zeros(1, 32)
    spike[0, 10] = 1.0
    got = L.distortion_loss(RaySamples(bins), spike, torch.ones(1), torch.full((1,), 3.0)).item()
    assert got == pytest.approx((1 / 32) / 3, rel=1e-5)


def _flat_kplanes(value: float = 0.3) -> KPlanesEncoding:
    """x, y, z and a k axis of 5 vertices; every plane constant. Pair 2 is (x, k): W along x (4), H along k (5)."""
    g = KPlanesEncoding([4, 4, 4, 5], 1)
    assert g.pairs[2] == (0, 3) and tuple(g.planes[2].shape) == (1, 1, 5, 4)
    with torch.no_grad():
        for p in g.planes:
            p.fill_(value)
    return g


def test_plane_tv_of_a_k_plane_is_along_its_spatial_axis_only():
    # six planes; the mean of their TVs. A ramp 0, 1, 2, 3 along x (W) of the (x, k) plane: squared steps of 1, so
    # that plane's TV is 1 and the mean 1 / 6
    g = _flat_kplanes()
    with torch.no_grad():
        g.planes[2].copy_(torch.arange(4.0).view(1, 1, 1, 4).expand(1, 1, 5, 4))
    assert L.plane_tv(g).item() == pytest.approx(1 / 6, rel=1e-6)
    # the same ramp along k (H) instead: the k axis is not regularised by TV (K-Planes), so 0
    g = _flat_kplanes()
    with torch.no_grad():
        g.planes[2].copy_(torch.arange(5.0).view(1, 1, 5, 1).expand(1, 1, 5, 4))
    assert L.plane_tv(g).item() == 0


def test_k_smoothness_is_along_the_k_axis():
    # (x, k) plane quadratic along k (H): 0, 1, 4, 9, 16 has a second difference of 2, squared 4; the other two k
    # planes are flat, so the mean over the three k planes is 4 / 3
    g = _flat_kplanes()
    with torch.no_grad():
        g.planes[2].copy_((torch.arange(5.0) ** 2).view(1, 1, 5, 1).expand(1, 1, 5, 4))
    assert L.k_smoothness(g).item() == pytest.approx(4 / 3, rel=1e-6)
    # quadratic along x (W) and constant along k: smooth in k, so 0
    g = _flat_kplanes()
    with torch.no_grad():
        g.planes[2].copy_((torch.arange(4.0) ** 2).view(1, 1, 1, 4).expand(1, 1, 5, 4))
    assert L.k_smoothness(g).item() == 0


def test_focal_mask_loss_on_samples_does_not_train_the_rendering_weights():
    """The docstring: the per-sample CE is weighted by the (detached) rendering weights."""
    weights = torch.tensor([[0.7, 0.2], [0.5, 0.5]], requires_grad=True)
    logits = torch.tensor([[[1.0, 0.0], [0.0, 2.0]], [[0.5, 0.0], [0.0, 0.0]]], requires_grad=True)
    L.focal_mask_loss_samples(weights, logits, torch.tensor([0, 1])).backward()
    assert weights.grad is None
    assert logits.grad is not None and logits.grad.abs().sum() > 0


def test_pdf_samples_of_a_uniform_pdf_are_stratified():
    # uniform weights on [0, 1]: the CDF is the identity, so edge i is u_i = (i + U_i) / (n + 1), inside its stratum
    n = 8
    s = RaySamples(torch.linspace(0, 1, 9).expand(64, 9))
    g = torch.Generator().manual_seed(0)
    fine = pdf_samples(s, torch.ones(64, 8), n, jitter=True, generator=g)
    i = torch.arange(n + 1.0)
    assert torch.all(fine.bins >= i / (n + 1) - 1e-6) and torch.all(fine.bins <= (i + 1) / (n + 1) + 1e-6)
    assert torch.all(fine.deltas > 0)
    # without jitter every edge is its stratum's centre
    mid = pdf_samples(s, torch.ones(64, 8), n, jitter=False)
    torch.testing.assert_close(mid.bins, ((i + 0.5) / (n + 1)).expand(64, n + 1))


def test_uniform_jitter_moves_every_edge_inside_its_cell():
    # n = 4 cells on [0, 1]: an inner edge i/4 moves uniformly within +-1/8, the first within [0, 1/8], the last
    # within [7/8, 1]. Over 10 000 rays the mean of an inner edge is i/4, of the first 1/16, of the last 15/16
    n, rays = 4, 10_000
    nears, fars = torch.zeros(rays), torch.ones(rays)
    plain = uniform_samples(nears, fars, n).bins
    torch.testing.assert_close(plain[0], torch.linspace(0, 1, n + 1))
    g = torch.Generator().manual_seed(0)
    jit = uniform_samples(nears, fars, n, jitter=True, generator=g).bins
    assert (jit - plain).abs().amax(0).min() > 0.1  # every edge moves, by up to the 1/8 it may
    assert torch.all((jit - plain).abs() <= 1 / 8 + 1e-6)
    assert torch.all(jit[:, 0] >= 0) and torch.all(jit[:, -1] <= 1)
    expect_mean = torch.tensor([1 / 16, 0.25, 0.5, 0.75, 15 / 16])
    torch.testing.assert_close(jit.mean(0), expect_mean, atol=5e-3, rtol=0)


def test_proposal_anneal_follows_the_schlick_bias():
    # Mip-NeRF 360 eq. 18: b f / ((b - 1) f + 1) with f = step / anneal_max_steps; b = 10 and f = 1/2 give 10/11
    from stages.model.config import SamplingConfig
    from stages.model.ray_samplers import ProposalSchedule

    sched = ProposalSchedule(SamplingConfig(anneal_slope=10.0, anneal_max_steps=100))
    assert sched.anneal(0) == 0.0
    assert sched.anneal(50) == pytest.approx(10 / 11, rel=1e-9)
    assert sched.anneal(10) == pytest.approx(1.0 / 1.9, rel=1e-9)  # f = 0.1: 1 / (0.9 + 1)
    assert sched.anneal(100) == pytest.approx(1.0) and sched.anneal(500) == pytest.approx(1.0)
