"""Language targets: phrases, shapes, the npz contract and the CLI."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from stages.language import LanguageTargets, ObjectVocabulary, build_targets
from stages.language import cli as language_cli
from stages.scene import InputError


def test_state_phrases_from_prompts_or_generated():
    vocab = ObjectVocabulary.from_prompts(
        ["fridge", "wall_cabinet"], {"fridge": {"states": {0: "shut fridge", 1: "fridge left open"}}})
    assert vocab.entry("fridge").state_phrase(0.0) == "shut fridge"
    assert vocab.entry("fridge").state_phrase(1.0) == "fridge left open"
    cab = vocab.entry("wall_cabinet")
    assert [cab.state_phrase(v) for v in (0.0, 0.5, 0.3, 1.0)] == [
        "closed wall cabinet", "half open wall cabinet", "30 percent open wall cabinet", "open wall cabinet"]
    with pytest.raises(InputError, match="unknown objects"):
        ObjectVocabulary.from_prompts(["fridge"], {"oven": {}})


def test_build_targets_shapes_and_phrases(encoder):
    vocab = ObjectVocabulary.from_prompts(["fridge", "drawer"], {})
    t = build_targets(vocab, encoder, levels=(1.0, 0.0))
    assert t.states.tolist() == [0.0, 1.0]
    assert t.embeddings.shape == (2, 2, encoder.dim) and t.background.shape == (encoder.dim,)
    assert t.phrases == [["closed fridge", "open fridge"], ["closed drawer", "open drawer"]]
    np.testing.assert_allclose(np.linalg.norm(t.embeddings, axis=-1), 1.0, atol=1e-5)
    np.testing.assert_allclose(t.embeddings[0, 1], encoder.encode(["open fridge"])[0])
    with pytest.raises(InputError, match="distinct values"):
        build_targets(vocab, encoder, levels=(0.0, 1.5))


def test_targets_cli_writes_the_contract(tmp_path, tiny_dataset, encoder, monkeypatch):
    ds = tiny_dataset
    monkeypatch.setattr(language_cli, "encoder_from_args", lambda args: encoder)
    out = tmp_path / "targets.npz"
    assert language_cli.main(["targets", "--data", str(ds.root), "--out", str(out), "--levels", "0,0.5,1"]) == 0
    with np.load(out, allow_pickle=False) as d:  # what the model stage does: numpy only
        assert d["objects"].tolist() == ds.objects
        assert d["states"].tolist() == [0.0, 0.5, 1.0]
        assert d["embeddings"].shape == (3, 3, encoder.dim) and d["embeddings"].dtype == np.float32
        assert d["background"].shape == (encoder.dim,)
        assert str(d["encoder"]) == encoder.name
    back = LanguageTargets.read(out)
    assert back.phrases[0] == ["closed object0", "half open object0", "open object0"]


def test_targets_cli_rejects_bad_input(tmp_path, tiny_dataset, capsys, monkeypatch, encoder):
    ds = tiny_dataset
    (ds.root / "prompts.yaml").write_text(yaml.safe_dump({"oven": {"synonyms": ["stove"]}}))
    monkeypatch.setattr(language_cli, "encoder_from_args", lambda args: encoder)
    assert language_cli.main(["targets", "--data", str(ds.root), "--out", str(tmp_path / "t.npz")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "prompts.yaml" in err and "unknown objects ['oven']" in err
    assert not (tmp_path / "t.npz").exists()
    with pytest.raises(InputError, match="not a language targets file"):
        LanguageTargets.read(tmp_path / "prompts.yaml")
