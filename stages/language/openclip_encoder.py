"""Optional OpenCLIP encoder (text and image) with the paper's masked-crop targets.

LiveScene trains its language table against OpenCLIP ViT-B-16 image features
of each object's masked crop. open_clip is not a dependency of this project and
nothing is ever downloaded: the encoder loads only a weights file the user
already has, and says how to get going when the package or the file is absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .encoder import CachedEncoder, EncoderError, normalize_rows


def masked_object_crop(image: np.ndarray, mask: np.ndarray, pad: float = 0.1,
                       fill: float = 1.0) -> np.ndarray | None:
    """The bounding-box crop of one object, pixels outside its mask set to ``fill``.

    ``image`` is ``[H, W, 3]`` float in [0, 1], ``mask`` ``[H, W]`` bool. The box
    is padded by ``pad`` of its size (clipped to the image) so the crop keeps
    the object's outline. Returns None when the mask is empty.
    """
    ys, xs = np.nonzero(mask)
    if ys.size == 0:
        return None
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    py, px = round(pad * (y1 - y0)), round(pad * (x1 - x0))
    h, w = mask.shape
    y0, y1, x0, x1 = max(0, y0 - py), min(h, y1 + py), max(0, x0 - px), min(w, x1 + px)
    crop = np.array(image[y0:y1, x0:x1], dtype=np.float32, copy=True)
    crop[~mask[y0:y1, x0:x1]] = fill
    return crop


class OpenClipEncoder(CachedEncoder):
    """OpenCLIP text and image encoder from a local checkpoint (default architecture ViT-B-16)."""

    def __init__(self, weights: str | Path, model_name: str = "ViT-B-16", device: str = "cpu",
                 cache_dir: str | Path | None = None) -> None:
        weights = Path(weights)
        try:
            import open_clip
            import torch
        except ImportError as exc:
            raise EncoderError(weights, "the optional package open_clip is not installed",
                               "pip install open_clip_torch, or use the default encoder (--encoder minilm)") from exc
        if not weights.is_file():
            raise EncoderError(weights, "OpenCLIP weights file not found",
                               f"pass the local path of a {model_name} checkpoint; nothing is downloaded")
        self.name = f"open_clip/{model_name}/{weights.name}"
        self._torch = torch
        self._device = device
        model, _, preprocess = open_clip.create_model_and_transforms(model_name, pretrained=str(weights),
                                                                     device=device)
        self._model = model.eval()
        self._preprocess = preprocess
        self._tokenizer = open_clip.get_tokenizer(model_name)
        with torch.no_grad():
            self._dim = int(self._model.encode_text(self._tokenizer(["x"]).to(device)).shape[-1])
        super().__init__(cache_dir)

    @property
    def dim(self) -> int:
        return self._dim

    def _encode_new(self, texts: list[str]) -> np.ndarray:
        with self._torch.no_grad():
            feats = self._model.encode_text(self._tokenizer(texts).to(self._device))
        return feats.float().cpu().numpy()

    def encode_images(self, images: list[np.ndarray]) -> np.ndarray:
        """``[N, D]`` unit image features of float [0, 1] ``[H, W, 3]`` images (not cached)."""
        from PIL import Image

        batch = [self._preprocess(Image.fromarray((np.clip(im, 0, 1) * 255).astype(np.uint8))) for im in images]
        with self._torch.no_grad():
            feats = self._model.encode_image(self._torch.stack(batch).to(self._device))
        return normalize_rows(feats.float().cpu().numpy())

    def crop_targets(self, image: np.ndarray, onehot_mask: np.ndarray) -> np.ndarray:
        """Paper-style targets of one frame: ``[objects + 1, D]``, one masked-crop feature per channel.

        Channels with no pixel in this frame get a zero row (their rays carry
        no label, so no target is needed). The background channel is the last.
        """
        rows = np.zeros((onehot_mask.shape[-1], self.dim), dtype=np.float32)
        crops, where = [], []
        for k in range(onehot_mask.shape[-1]):
            crop = masked_object_crop(image, onehot_mask[..., k])
            if crop is not None:
                crops.append(crop)
                where.append(k)
        if crops:
            rows[where] = self.encode_images(crops)
        return rows
