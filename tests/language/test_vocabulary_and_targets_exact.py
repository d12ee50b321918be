"""Vocabulary reading, targets contract and the embedding cache: cases a mutation audit found unchecked."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from stages.language import EmbeddingCache, LanguageTargets, ObjectVocabulary, build_crop_targets, build_targets
from stages.language.vocabulary import read_object_names
from stages.scene import InputError
from tests.conftest import make_tiny_dataset
from tests.language.table_encoder import TableEncoder, unit


def test_mapping_ids_order_the_objects_as_numbers(tmp_path):
    path = tmp_path / "mapping.yaml"
    path.write_text("".join(f"{i}: o{i}\n" for i in (10, 2, 11, 1, 3, 4, 5, 6, 7, 8, 9)))
    assert read_object_names(path) == [f"o{i}" for i in range(1, 12)]  # as strings 10 and 11 came before 2


def test_prompts_forms_a_user_writes():
    vocabulary = ObjectVocabulary.from_prompts(
        ["fridge", "drawer"],
        {"fridge": {"synonyms": "chiller", "states": ["shut fridge", "ajar fridge", "wide open fridge"]}},
    )
    fridge = vocabulary.entry("fridge")
    assert fridge.aliases == ["fridge", "chiller"]  # one synonym as a string, not its letters
    assert fridge.state_phrases == {0.0: "shut fridge", 0.5: "ajar fridge", 1.0: "wide open fridge"}  # evenly
    assert vocabulary.entry("drawer").state_phrase(0.29) == "29 percent open drawer"  # 100 * 0.29 = 28.999...
    with pytest.raises(InputError, match="entry of 'fridge' is not a mapping"):
        ObjectVocabulary.from_prompts(["fridge"], {"fridge": "refrigerator"})


ENCODER = {"closed fridge": unit(1.0), "open fridge": unit(0.0, 1.0), "background": unit(0.0, 0.0, 1.0)}


def test_targets_background_and_levels():
    vocabulary = ObjectVocabulary.from_prompts(["fridge"], {})
    targets = build_targets(vocabulary, TableEncoder(ENCODER))
    np.testing.assert_array_equal(targets.background, unit(0.0, 0.0, 1.0))
    np.testing.assert_array_equal(targets.embeddings[0], [unit(1.0), unit(0.0, 1.0)])
    for levels in [(-0.5, 1.0), (0.0, 0.0, 1.0)]:
        with pytest.raises(InputError, match="are not distinct values in"):
            build_targets(vocabulary, TableEncoder(ENCODER), levels)


def test_a_targets_file_of_mismatched_shapes_is_refused(tmp_path):
    path = tmp_path / "targets.npz"
    LanguageTargets(
        objects=["fridge", "drawer"],
        states=np.array([0.0, 1.0]),
        embeddings=np.zeros((1, 2, 8)),
        background=np.zeros(8),
        phrases=[["a", "b"]],
        encoder="e",
    ).write(path)
    with pytest.raises(InputError, match=r"do not match 2 objects x 2 states"):
        LanguageTargets.read(path)


class _ImageEncoder(TableEncoder):
    """An image's feature is the axis of its grey level inside the mask (0.2 -> 1, 0.4 -> 2, 0.6 -> 3)."""

    def encode_images(self, images):
        return np.stack([np.eye(self.dim)[round(float(np.min(im)) * 5)] for im in images])


def test_crop_targets_average_the_frames_nearest_each_level_into_a_unit_vector(tmp_path):
    ds = make_tiny_dataset(tmp_path / "scene")
    train = ds.frames_in("train")  # frames 1, 3, 5
    for frame, grey, state in zip(train, (51, 102, 153), (0.1, 0.2, 0.9), strict=True):
        cv2.imwrite(str(ds.image_path(frame)), np.full((ds.camera.height, ds.camera.width, 3), grey, np.uint8))
        frame.state = {**frame.state, "object0": state}
        assert ds.load_mask(frame)[..., 0].any()
    targets = build_crop_targets(ds, _ImageEncoder({}))
    # level 0: frames at 0.1 and 0.2 (axes 1 and 2), their mean made unit; level 1: the frame at 0.9 (axis 3)
    np.testing.assert_allclose(targets.embeddings[0, 0], unit(0.0, 2**-0.5, 2**-0.5), rtol=1e-6)
    np.testing.assert_allclose(targets.embeddings[0, 1], unit(0.0, 0.0, 0.0, 1.0), rtol=1e-6)
    assert targets.phrases[0] == ["crops: 2 frames", "crops: 1 frames"]


def test_a_cache_file_of_another_encoder_is_not_read(tmp_path):
    cache = EmbeddingCache(tmp_path, "encoder a")
    np.savez(cache.path, texts=np.array(["open"]), vectors=np.ones((1, 2), np.float32), encoder=np.array("encoder b"))
    assert cache.load() == {}


def test_an_unwritable_cache_warns_once(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    encoder = TableEncoder({})
    encoder._disk = EmbeddingCache(blocker / "cache", encoder.name)  # a folder under a file cannot be made
    with pytest.warns(UserWarning, match="cannot be written"):
        encoder.encode(["open"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        encoder.encode(["closed"])  # the cache was given up: no second warning, no second try
