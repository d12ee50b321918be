"""Image and mask metrics: PSNR (whole image or a pixel mask), SSIM (Gaussian 11x11), IoU, and LPIPS when it
is available.

LPIPS needs pretrained network weights that cannot be downloaded here; it is
computed only when torchvision and the weights are already on disk, and
otherwise recorded as not available (never estimated).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np


def psnr(pred: np.ndarray, target: np.ndarray, mask: np.ndarray | None = None, data_range: float = 1.0) -> float:
    """Peak signal-to-noise ratio in dB over all pixels, or over ``mask`` (``[H, W]`` bool) only.

    Returns NaN for an empty mask and +inf for identical images.
    """
    pred = np.asarray(pred, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if pred.shape != target.shape:
        raise ValueError(f"prediction {pred.shape} and target {target.shape} differ in shape")
    err = (pred - target) ** 2
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if not mask.any():
            return float("nan")
        err = err[mask]
    mse = float(err.mean())
    if mse == 0.0:
        return float("inf")
    return 10.0 * math.log10(data_range**2 / mse)


SSIM_FORM = "Gaussian window 11x11, sigma 1.5 (torchmetrics; the form nerfstudio and the LiveScene paper report)"


def ssim(pred: np.ndarray, target: np.ndarray, data_range: float = 1.0) -> float:
    """Structural similarity of two ``[H, W, 3]`` images in the standard form (``SSIM_FORM``).

    torchmetrics computes it with a Gaussian 11x11 window (sigma 1.5) and needs no weights, so the numbers
    compare with published ones; an image smaller than the window gets the largest odd window that fits, with
    sigma scaled alike (torchmetrics sizes the window from sigma).
    """
    import torch
    from torchmetrics.functional.image import structural_similarity_index_measure

    pred = np.asarray(pred, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if pred.shape != target.shape:
        raise ValueError(f"prediction {pred.shape} and target {target.shape} differ in shape")
    win = min(11, *pred.shape[:2])
    win -= 1 - win % 2  # the window must be odd

    def nchw(x: np.ndarray) -> torch.Tensor:
        # float32, as nerfstudio feeds it: torch's float64 depthwise conv2d takes a slow path on the CPU (0.3 s
        # against 8 ms for a 256x192 image); the result moves by ~1e-6 (test_metrics.py)
        return torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32)).permute(2, 0, 1)[None]

    # on one torch thread: the convolutions' and the mean's sums are split by the thread count, so with the
    # process's threads the value moved in the 8th digit between a 1- and a 2-thread evaluation (metrics.json
    # would then depend on the cores Snakemake gives the job)
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        value = structural_similarity_index_measure(nchw(pred), nchw(target), data_range=data_range,
                                                    kernel_size=win, sigma=1.5 * win / 11)
    finally:
        torch.set_num_threads(previous)
    return float(value)


def iou(pred: np.ndarray, truth: np.ndarray) -> float:
    """Intersection over union of two boolean masks; NaN when both are empty (undefined)."""
    pred = np.asarray(pred, dtype=bool)
    truth = np.asarray(truth, dtype=bool)
    union = int(np.logical_or(pred, truth).sum())
    if union == 0:
        return float("nan")
    return float(np.logical_and(pred, truth).sum()) / union


def summarize(values: list[float]) -> dict[str, Any]:
    """Mean, std (population), min, max, count and 95% CI of the mean of the finite values.

    ``ci95`` is ``[lo, hi]`` from Student's t with n - 1 degrees of freedom and the sample (n - 1) std: the
    interval a reader needs to tell a difference from noise. None when n < 2 (no spread to estimate);
    the other values are None when there are no finite values at all.
    """
    arr = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=np.float64)
    if arr.size == 0:
        return {"mean": None, "std": None, "min": None, "max": None, "n": 0, "ci95": None}
    mean = float(arr.mean())
    return {"mean": mean, "std": float(arr.std()), "min": float(arr.min()), "max": float(arr.max()),
            "n": int(arr.size), "ci95": _ci95(arr, mean)}


def _ci95(arr: np.ndarray, mean: float) -> list[float] | None:
    """Student-t 95% confidence interval of the mean of ``arr``; None for fewer than two values."""
    n = int(arr.size)
    if n < 2:
        return None
    from scipy import stats

    half = float(stats.t.ppf(0.975, n - 1)) * float(arr.std(ddof=1)) / math.sqrt(n)
    return [mean - half, mean + half]


def lpips_weights_dir() -> Path:
    """Where LPIPS's AlexNet backbone must lie (torch hub's cache: ``$TORCH_HOME/hub/checkpoints``,
    file ``alexnet-owt-7be5be79.pth``); nothing is downloaded at run time (docs/language.md)."""
    return Path(os.environ.get("TORCH_HOME", Path.home() / ".cache" / "torch")) / "hub" / "checkpoints"


class Lpips:
    """LPIPS (AlexNet) through torchmetrics, only from weights already on this machine.

    ``available`` says whether it can run; ``status`` says why not. The
    torchvision AlexNet backbone and the LPIPS linear layers must both be
    present locally (torch hub cache), since nothing may be downloaded.
    """

    def __init__(self) -> None:
        self.available = False
        self.status = "not available"
        self._metric = None
        try:
            import torchvision  # noqa: F401
            from torchmetrics.image.lpip import LearnedPerceptualImagePatchSimilarity
        except ImportError as exc:
            self.status = (f"not available: {exc.name or exc} is not installed (pip install -e '.[lpips]', then put "
                           f"the AlexNet weights in {lpips_weights_dir()})")
            return
        except Exception as exc:  # a torchvision built for another torch fails at import with a RuntimeError
            self.status = f"not available: torchvision does not load beside this torch ({type(exc).__name__}: {exc})"
            return
        hub = lpips_weights_dir()
        if not any(hub.glob("alexnet-*.pth")):
            self.status = f"not available: no AlexNet weights in {hub} (and none may be downloaded)"
            return
        try:
            self._metric = LearnedPerceptualImagePatchSimilarity(net_type="alex", normalize=True)
        except Exception as exc:  # weights missing or corrupt: say so, do not guess a value
            self.status = f"not available: {type(exc).__name__}: {exc}"
            return
        self.available = True
        self.status = "computed (torchmetrics, AlexNet)"

    def __call__(self, pred: np.ndarray, target: np.ndarray) -> float | None:
        if not self.available or self._metric is None:
            return None
        import torch

        a = torch.from_numpy(np.ascontiguousarray(pred, dtype=np.float32)).permute(2, 0, 1)[None].clamp(0, 1)
        b = torch.from_numpy(np.ascontiguousarray(target, dtype=np.float32)).permute(2, 0, 1)[None].clamp(0, 1)
        with torch.no_grad():
            return float(self._metric(a, b))
