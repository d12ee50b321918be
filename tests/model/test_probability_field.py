"""The argmax k-projection: each sample takes the state of the object whose logit wins."""

from __future__ import annotations

import torch

from stages.model.config import ProbabilityConfig
from stages.model.fields import ProbabilityField


def test_projection_picks_kappa_of_the_argmax_object_ignoring_background():
    field = ProbabilityField(ProbabilityConfig(), n_objects=3)
    states = torch.tensor([[0.1, 0.5, 0.9]]).expand(4, 3)
    logits = torch.tensor([
        [5.0, 0.0, 0.0, 0.0],   # object 0
        [0.0, 0.0, 3.0, 0.0],   # object 2
        [0.0, 2.0, 1.0, 9.0],   # background largest: argmax over objects only -> object 1
        [-1.0, -2.0, -0.5, -3.0],  # object 2
    ])
    k, u = field.project(logits, states)
    assert u.tolist() == [0, 2, 1, 2]
    assert torch.allclose(k, torch.tensor([0.1, 0.9, 0.5, 0.9]))


def test_projection_keeps_state_gradient_and_rejects_unsure_samples():
    field = ProbabilityField(ProbabilityConfig(rejection_threshold=0.6, static_value=0.0), n_objects=2)
    states = torch.tensor([[0.3, 0.8], [0.3, 0.8]], requires_grad=True)
    logits = torch.tensor([[10.0, 0.0, 0.0], [0.0, 0.1, 0.0]])  # sure about object 0; unsure about object 1
    k, u = field.project(logits, states)
    assert u.tolist() == [0, 1]
    assert torch.allclose(k, torch.tensor([0.3, 0.0]))
    k.sum().backward()
    assert states.grad[0].tolist() == [1.0, 0.0]


def test_static_row_moves_objects_off_the_static_vertex():
    config = ProbabilityConfig(rejection_threshold=0.6, static_value=0.0, static_row=True)
    field = ProbabilityField(config, n_objects=2, k_resolution=16)
    states = torch.tensor([[0.0, 1.0]]).expand(3, 2)
    logits = torch.tensor([[10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.1, 0.0]])  # closed, open, unsure
    k, _ = field.project(logits, states)
    # a closed object reads the second vertex, an open one the last, a rejected (static) sample the first alone
    assert torch.allclose(k, torch.tensor([1 / 15, 1.0, 0.0]))
    plain = ProbabilityField(ProbabilityConfig(rejection_threshold=0.6), n_objects=2, k_resolution=16)
    assert torch.allclose(plain.project(logits, states)[0], torch.tensor([0.0, 1.0, 0.0]))  # one shared row


def test_field_learns_regions_from_position():
    """The full field (tri-plane + decoder) fed positions returns alpha + 1 logits per sample."""
    torch.manual_seed(0)
    field = ProbabilityField(ProbabilityConfig(resolution=8, channels=4, hidden=8), n_objects=2)
    pos = torch.rand(32, 3) * 2 - 1
    logits = field(pos, torch.rand(32, 2))
    assert logits.shape == (32, 3) and torch.isfinite(logits).all()


def _softmax_projection(logits: torch.Tensor, n_objects: int, threshold: float) -> tuple[torch.Tensor, torch.Tensor]:
    """The projection written with an explicit softmax (what ``project`` computes without forming it)."""
    probs = torch.softmax(logits, dim=-1)[:, :n_objects]
    best, u = probs.max(dim=-1)
    return best >= threshold, u


def test_projection_without_softmax_matches_the_softmax_formulation():
    torch.manual_seed(0)
    n_objects, threshold = 4, 0.5
    field = ProbabilityField(ProbabilityConfig(rejection_threshold=threshold, static_value=-1.0), n_objects)
    scales = torch.tensor([0.1, 1.0, 10.0, 60.0, 200.0]).repeat_interleave(1000)  # up to exp overflow
    logits = torch.randn(5000, n_objects + 1) * scales[:, None]
    states = torch.rand(5000, n_objects)
    k, u = field.project(logits, states)
    sure, u_ref = _softmax_projection(logits, n_objects, threshold)
    top2 = torch.softmax(logits, dim=-1)[:, :n_objects].topk(2, dim=-1).values
    distinct = top2[:, 0] > top2[:, 1]  # the softmax ties objects whose probabilities underflow to 0
    assert torch.equal(u[distinct], u_ref[distinct]) and float(distinct.float().mean()) > 0.8
    assert torch.equal(u, logits[:, :n_objects].argmax(dim=-1))  # the logits never tie here
    probs = top2[:, 0]
    clear = (probs - threshold).abs() > 1e-5  # rounding may only decide samples on the threshold itself
    k_ref = torch.where(sure, torch.gather(states, 1, u_ref[:, None])[:, 0], torch.full_like(k, -1.0))
    assert torch.equal(k[clear], k_ref[clear])
    assert 0.2 < float((k == -1.0).float().mean()) < 0.8  # both branches are exercised


def test_one_state_for_every_ray_gives_the_per_ray_result_and_gradients():
    torch.manual_seed(1)
    field = ProbabilityField(ProbabilityConfig(resolution=8, channels=4, hidden=8), n_objects=2)
    rays, samples = 6, 5
    pos = torch.rand(rays * samples, 3) * 2 - 1
    state = torch.tensor([[0.2, 0.9]])
    shared = field(pos, state.expand(rays, 2))                 # stride 0: folded into the bias
    per_ray = field(pos, state.repeat(rays, 1))                # one row per ray: added in place
    per_sample = field(pos, state.repeat(rays * samples, 1))   # one row per sample
    assert torch.allclose(shared, per_ray, atol=1e-6) and torch.allclose(per_ray, per_sample, atol=1e-6)
    grads = []
    for states in (state.expand(rays, 2), state.repeat(rays, 1)):
        field.zero_grad()
        field(pos, states).square().sum().backward()
        grads.append([p.grad.clone() for p in field.parameters()])
    for a, b in zip(*grads, strict=True):
        assert torch.allclose(a, b, atol=1e-5)


def test_state_input_none_gives_every_state_the_same_regions():
    """``state_input: none``: an object's region is its swept space, so no state change reassigns a sample."""
    torch.manual_seed(3)
    pos = torch.rand(64, 3) * 2 - 1
    before, after = torch.tensor([[0.1, 0.5, 0.7]]), torch.tensor([[0.9, 0.0, 1.0]])
    for mode, moves in (("none", False), ("all", True)):
        field = ProbabilityField(ProbabilityConfig(resolution=8, channels=4, hidden=8, state_input=mode), n_objects=3)
        assert field.decoder[0].in_features == 4 + (3 if mode == "all" else 0)
        for a, b in ((field(pos, before.expand(64, 3)), field(pos, after.expand(64, 3))),
                     (field(pos, before.repeat(64, 1)), field(pos, after.repeat(64, 1)))):
            assert torch.isfinite(a).all() and (not torch.allclose(a, b, atol=1e-6)) == moves


def _tiny_livescene(n_objects: int = 2):
    from stages.model.config import ModelConfig
    from stages.model.methods import LiveSceneModel, SceneInfo

    cfg = ModelConfig()
    cfg.field.base_resolution, cfg.field.channels, cfg.field.scales = 8, 4, [1]
    cfg.proposal.resolutions, cfg.sampling.num_proposal_samples = [[8, 4]], [8]
    cfg.probability.resolution = 8
    torch.manual_seed(0)
    return LiveSceneModel(cfg, SceneInfo(objects=[f"o{i}" for i in range(n_objects)], n_frames=4))


def test_livescene_maps_kappa_to_the_planes_k_axis_in_minus_one_to_one():
    # the planes' k axis spans [-1, 1] like x, y and z (grid_sample's convention): kappa 0, 0.25, 1 -> -1, -0.5, 1
    model = _tiny_livescene()
    pos = torch.tensor([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0], [-0.5, 0.5, 0.0]])
    states = torch.tensor([[0.0, 0.7], [0.25, 0.7], [1.0, 0.7]])
    logits = torch.tensor([[4.0, 0.0, 0.0]]).expand(3, 3)  # object 0 wins everywhere
    coords = model.coordinates(pos, states, logits, torch.zeros(3))
    assert torch.equal(coords[:, :3], pos)
    torch.testing.assert_close(coords[:, 3], torch.tensor([-1.0, -0.5, 1.0]))


def test_every_sample_reads_its_own_rays_state(monkeypatch):
    # two rays of five samples, object 0 wins at every sample: ray 0 (kappa_0 = 0) must sit at k = -1 throughout,
    # ray 1 (kappa_0 = 1) at k = +1
    from stages.model.ray_samplers import uniform_samples
    from stages.model.rays import RayBundle

    model = _tiny_livescene()
    states = torch.tensor([[0.0, 1.0], [1.0, 0.0]])
    rays = RayBundle(torch.zeros(2, 3), torch.tensor([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), torch.full((2,), 0.05),
                     torch.ones(2), states)
    monkeypatch.setattr(model.probability_field, "forward",
                        lambda pos, st, grids: torch.tensor([[5.0, 0.0, 0.0]]).expand(pos.shape[0], 3))
    seen = []
    coordinates = model.coordinates
    monkeypatch.setattr(model, "coordinates", lambda *a: seen.append(coordinates(*a)) or seen[-1])
    with torch.no_grad():
        model._level(rays, uniform_samples(rays.nears, rays.fars, 5), states, 0, final=False, grad_density=False)
    k = seen[0][:, 3].view(2, 5)
    assert torch.equal(k, torch.tensor([[-1.0] * 5, [1.0] * 5]))
