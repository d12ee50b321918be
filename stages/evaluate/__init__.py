"""Evaluation of a trained run: held-out image quality, control of unseen state combinations, grounding."""

from .evaluation import EVALUATE_VERSION, EvaluateConfig, Evaluator, evaluate_run
from .metrics import Lpips, iou, psnr, ssim, summarize
from .truth_source import TruthSource, read_sim3
from .unseen_states import StateCombination, novelty, unseen_combinations

__all__ = [
    "EVALUATE_VERSION",
    "EvaluateConfig",
    "Evaluator",
    "Lpips",
    "StateCombination",
    "TruthSource",
    "evaluate_run",
    "iou",
    "novelty",
    "psnr",
    "read_sim3",
    "ssim",
    "summarize",
    "unseen_combinations",
]
