"""Near and far distances of rays through the normalised scene box (slab method, ``aabb_near_far``)."""

from __future__ import annotations

import pytest
import torch

from stages.model.scene_normalization import aabb_near_far


def test_a_ray_through_the_box_enters_and_leaves_at_its_faces():
    # from (-3, 0.2, 0) along +x: the slabs x = -1 and x = +1 are 2 and 4 away
    near, far = aabb_near_far(torch.tensor([[-3.0, 0.2, 0.0]]), torch.tensor([[1.0, 0.0, 0.0]]), near_plane=0.05)
    assert near.item() == pytest.approx(2.0) and far.item() == pytest.approx(4.0)


def test_a_camera_inside_the_box_starts_at_the_near_plane():
    # from the centre along +x the slab entry is at t = -1, behind the camera: sampling starts at near_plane instead
    near, far = aabb_near_far(torch.zeros(1, 3), torch.tensor([[1.0, 0.0, 0.0]]), near_plane=0.05)
    assert near.item() == pytest.approx(0.05) and far.item() == pytest.approx(1.0)


def test_a_ray_that_misses_the_box_gets_a_tiny_interval_past_the_near_plane():
    # from (0, 5, 0) along +x the ray never reaches |y| <= 1: exit before entry. The docstring: a tiny interval just
    # past near_plane, so every delta is >= 0 and the ray renders background
    near, far = aabb_near_far(torch.tensor([[0.0, 5.0, 0.0]]), torch.tensor([[1.0, 0.0, 0.0]]), near_plane=0.05)
    assert near.item() == pytest.approx(0.05)
    assert 0 < far.item() - near.item() <= 1e-3
