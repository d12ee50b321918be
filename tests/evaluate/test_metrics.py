"""Metric functions against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stages.evaluate import Lpips, iou, novelty, psnr, ssim, summarize, unseen_combinations
from stages.evaluate.unseen_states import observed_levels


def test_psnr_of_known_noise():
    rng = np.random.default_rng(0)
    target = rng.uniform(0.2, 0.8, (10, 12, 3))
    noise = 0.05 * rng.choice([-1.0, 1.0], target.shape)  # |error| = 0.05 everywhere: MSE = 0.0025
    assert psnr(target + noise, target) == pytest.approx(10 * math.log10(1 / 0.0025), abs=1e-9)  # 26.0206 dB
    assert psnr(target + noise, target, data_range=2.0) == pytest.approx(10 * math.log10(4 / 0.0025), abs=1e-9)
    assert psnr(target, target) == math.inf


def test_psnr_over_a_mask():
    target = np.zeros((4, 4, 3))
    pred = target.copy()
    pred[:2] = 0.1  # error only in the top half
    top = np.zeros((4, 4), bool)
    top[:2] = True
    assert psnr(pred, target, top) == pytest.approx(20.0)
    assert psnr(pred, target) == pytest.approx(10 * math.log10(1 / 0.005))
    assert math.isinf(psnr(pred, target, ~top))
    assert math.isnan(psnr(pred, target, np.zeros((4, 4), bool)))
    with pytest.raises(ValueError, match="differ in shape"):
        psnr(pred, target[:3])


def test_ssim_identity_and_ordering():
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 1, (16, 16, 3))
    assert ssim(img, img) == pytest.approx(1.0)
    slight = np.clip(img + rng.normal(0, 0.02, img.shape), 0, 1)
    heavy = np.clip(img + rng.normal(0, 0.3, img.shape), 0, 1)
    assert 1.0 > ssim(slight, img) > ssim(heavy, img)
    assert np.isfinite(ssim(img[:5, :5], img[:5, :5] * 0.9))  # smaller than the 11x11 window


def test_iou_hand_computed():
    a = np.zeros((4, 5), bool)
    b = np.zeros((4, 5), bool)
    a[0, :4] = True  # 4 pixels
    b[0, 2:] = True  # 3 pixels, 2 shared -> union 5
    assert iou(a, b) == pytest.approx(2 / 5)
    assert iou(a, a) == 1.0
    assert iou(a, ~a) == 0.0
    assert math.isnan(iou(np.zeros((2, 2), bool), np.zeros((2, 2), bool)))


def test_summarize_ignores_undefined_values():
    s = summarize([1.0, 3.0, float("nan"), None, float("inf")])
    # t(0.975, 1) = 12.7062; sample std sqrt(2), standard error 1
    assert s.pop("ci95") == pytest.approx([2.0 - 12.7062047, 2.0 + 12.7062047])
    assert s == {"mean": 2.0, "std": 1.0, "min": 1.0, "max": 3.0, "n": 2}
    assert summarize([])["mean"] is None and summarize([])["ci95"] is None


def test_summarize_ci95_is_student_t():
    # 1..5: mean 3, sample std sqrt(2.5), standard error 0.70711; t(0.975, 4) = 2.7764451 (tables)
    lo, hi = summarize([1.0, 2.0, 3.0, 4.0, 5.0])["ci95"]
    half = 2.7764451 * math.sqrt(2.5) / math.sqrt(5)
    assert (lo, hi) == (pytest.approx(3.0 - half, abs=1e-6), pytest.approx(3.0 + half, abs=1e-6))
    assert summarize([7.0])["ci95"] is None  # one value: no spread, no interval
    assert summarize([4.0, 4.0, 4.0])["ci95"] == [4.0, 4.0]
    wide = summarize([0.0, 10.0, 0.0, 10.0])["ci95"]
    assert wide[0] < 5.0 - 5.0 < wide[1]  # spread that large cannot exclude 0 at n = 4


def test_lpips_reports_status_not_a_made_up_value():
    metric = Lpips()
    if not metric.available:
        assert metric.status.startswith("not available")
        assert metric(np.zeros((8, 8, 3)), np.zeros((8, 8, 3))) is None
    else:
        assert metric(np.zeros((64, 64, 3)), np.zeros((64, 64, 3))) == pytest.approx(0.0, abs=1e-6)


def test_unseen_combinations_are_far_from_training():
    train = np.array([[t, t] for t in np.linspace(0, 1, 11)])  # the two objects always moved together
    combos = unseen_combinations(2, train, levels=(0.0, 0.5, 1.0), novelty_min=0.25)
    values = [c.values for c in combos]
    assert (0.0, 1.0) in values and (1.0, 0.0) in values
    for c in combos:
        assert c.values[c.anchor] == c.level
        other = c.values[1 - c.anchor]
        assert other != c.level  # the others are at other values
        assert c.novelty == pytest.approx(novelty(np.array(c.values), train))
        assert c.unseen == (c.novelty >= 0.25)
    assert len(values) == len(set(values))
    by_key = {c.values: c for c in combos}
    assert by_key[(0.0, 1.0)].novelty == pytest.approx(0.5)  # nearest diagonal point is (0.5, 0.5)
    assert novelty(np.array([0.3, 0.3]), np.empty((0, 2))) == math.inf


def test_unseen_combinations_scale_to_many_objects():
    # every object seen closed and open, always all together: each one open with the rest closed (and the reverse)
    combos = unseen_combinations(10, np.array([np.zeros(10), np.ones(10)]), levels=(0.0, 1.0))
    assert len(combos) == 20 and all(c.unseen for c in combos)


def test_unseen_combinations_keep_to_levels_each_object_was_seen_at():
    # the cabinet opens fully, the drawer only half way: asking for the drawer at 1 would test an appearance the
    # capture never showed, and the novelty search prefers exactly that level (farthest from every training state)
    train = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [0.0, 0.45]])
    assert observed_levels(train, (0.0, 0.5, 1.0)) == [[0.0, 0.5, 1.0], [0.0, 0.5]]
    kept = unseen_combinations(2, train)
    assert kept and all(c.values[1] != 1.0 for c in kept)
    assert (1.0, 0.5) in [c.values for c in kept if c.unseen]  # seen apart, never together: the test's point
    every = unseen_combinations(2, train, observed_within=None)
    assert any(c.values[1] == 1.0 and c.unseen for c in every)
    # an object that stays between the levels keeps the nearest one; no states at all: every level
    assert observed_levels(np.array([[0.3], [0.35]]), (0.0, 0.5, 1.0)) == [[0.5]]
    assert observed_levels(np.full((3, 1), np.nan), (0.0, 1.0)) == [[0.0, 1.0]]
    assert unseen_combinations(0, np.zeros((4, 0))) == []  # a room without objects has nothing to combine


def test_ssim_is_the_standard_gaussian_form():
    """Equal to scikit-image's Gaussian-weighted SSIM (Wang et al. 2004: 11x11, sigma 1.5, population
    covariance) away from the borders' handling, and clearly not the flat 7x7 form used before."""
    from skimage.metrics import structural_similarity

    rng = np.random.default_rng(3)
    img = rng.random((96, 128, 3))
    noisy = np.clip(img + 0.08 * rng.standard_normal(img.shape), 0, 1)
    ours = ssim(noisy, img)
    gaussian = structural_similarity(noisy, img, data_range=1.0, channel_axis=-1, gaussian_weights=True,
                                     sigma=1.5, use_sample_covariance=False)
    flat7 = structural_similarity(noisy, img, data_range=1.0, channel_axis=-1, win_size=7)
    assert ours == pytest.approx(gaussian, abs=2e-3)
    assert abs(ours - flat7) > 5 * abs(ours - gaussian)


def test_psnr_matches_torchmetrics():
    import torch
    from torchmetrics.functional.image import peak_signal_noise_ratio

    rng = np.random.default_rng(4)
    img = rng.random((24, 32, 3))
    noisy = np.clip(img + 0.05 * rng.standard_normal(img.shape), 0, 1)
    theirs = float(peak_signal_noise_ratio(torch.from_numpy(noisy), torch.from_numpy(img), data_range=1.0))
    assert psnr(noisy, img) == pytest.approx(theirs, rel=1e-6)


def test_ssim_equals_torchmetrics_on_a_reference_pair():
    """The report's SSIM is torchmetrics' StructuralSimilarityIndexMeasure (the module nerfstudio uses)."""
    import torch
    from torchmetrics.image import StructuralSimilarityIndexMeasure

    rng = np.random.default_rng(5)
    img = rng.random((64, 80, 3))
    blurred = np.clip(0.7 * img + 0.3 * np.roll(img, 1, axis=1) + 0.02 * rng.standard_normal(img.shape), 0, 1)
    module = StructuralSimilarityIndexMeasure(data_range=1.0)
    theirs = float(module(torch.from_numpy(blurred).permute(2, 0, 1)[None].float(),
                          torch.from_numpy(img).permute(2, 0, 1)[None].float()))
    assert ssim(blurred, img) == pytest.approx(theirs, abs=1e-4)


def test_ssim_in_float32_is_within_1e5_of_float64():
    """ssim() runs torchmetrics in float32 for speed; on an image pair of the demo's size and error the value
    stays within 1e-5 of the float64 computation."""
    import torch
    from torchmetrics.functional.image import structural_similarity_index_measure

    rng = np.random.default_rng(6)
    yy, xx = np.mgrid[0:192, 0:256] / 64.0
    img = np.clip(0.5 + 0.3 * np.sin(xx + 2 * yy)[..., None] * [1.0, 0.8, 0.6] + 0.05 * rng.random((192, 256, 3)), 0, 1)
    render = np.clip(img + 0.04 * rng.standard_normal(img.shape), 0, 1)
    double = float(structural_similarity_index_measure(torch.from_numpy(render).permute(2, 0, 1)[None],
                                                       torch.from_numpy(img).permute(2, 0, 1)[None], data_range=1.0))
    assert ssim(render, img) == pytest.approx(double, abs=1e-5)
    assert ssim(render, img) != double  # float32 really ran (else this test checks nothing)


def test_ssim_does_not_depend_on_the_thread_count():
    """An evaluation on 1 and on 2 torch threads (Snakemake hands a job the threads it may use) writes the same
    SSIM. A smooth image and a noisy copy of it: with the process's threads, seeds 1 and 2 differ in the 7th
    digit between 1 and 2 threads (a demo render did too); pure noise happens not to."""
    import cv2
    import torch

    previous = torch.get_num_threads()
    try:
        for seed in (1, 2):
            rng = np.random.default_rng(seed)
            base = cv2.GaussianBlur(rng.random((192, 256, 3)).astype(np.float32), (0, 0), 4)
            base = (base - base.min()) / (base.max() - base.min())
            pred = np.clip(base + 0.05 * rng.standard_normal(base.shape), 0, 1)
            values = []
            for threads in (1, 2, 4):
                torch.set_num_threads(threads)
                values.append(ssim(pred, base))
                assert torch.get_num_threads() == threads  # the caller's setting is put back
            assert values[0] == values[1] == values[2]
    finally:
        torch.set_num_threads(previous)
