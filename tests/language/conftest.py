"""Fixtures of the language tests: one offline text encoder per session, and a kitchen vocabulary."""

from __future__ import annotations

import os
import socket

import pytest

from stages.language import ObjectVocabulary, load_encoder

KITCHEN_OBJECTS = ["fridge", "upper_cabinet", "lower_cabinet", "drawer"]
KITCHEN_PROMPTS = {
    "fridge": {"synonyms": ["refrigerator"], "description": "a tall white refrigerator with one door"},
    "upper_cabinet": {"synonyms": ["wall cupboard"], "description": "a wooden wall cabinet above the counter"},
    "lower_cabinet": {"synonyms": ["base cupboard"], "description": "a wooden cabinet under the counter"},
    "drawer": {"synonyms": ["kitchen drawer"], "description": "a sliding drawer under the counter"},
}


def _no_network(*args, **kwargs):
    raise OSError("network access attempted while loading the offline encoder")


@pytest.fixture(scope="session")
def encoder(tmp_path_factory):
    """The default encoder, loaded with HF_HUB_OFFLINE=1 and every socket connection refused.

    Loaded once: building it takes several seconds on two cores.
    """
    import torch

    torch.set_num_threads(2)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("HF_HUB_OFFLINE", "1")
        mp.setenv("TRANSFORMERS_OFFLINE", "1")
        mp.setattr(socket.socket, "connect", _no_network)
        mp.setattr(socket, "create_connection", _no_network)
        enc = load_encoder("minilm", cache_dir=tmp_path_factory.mktemp("embeddings"))
        assert os.environ["HF_HUB_OFFLINE"] == "1"
        # encode while the network is still off: the first call builds tokenizer state lazily
        enc.encode(["warm up"])
    return enc


@pytest.fixture
def kitchen() -> ObjectVocabulary:
    return ObjectVocabulary.from_prompts(KITCHEN_OBJECTS, KITCHEN_PROMPTS)
