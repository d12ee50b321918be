"""Training a dataset in the published LiveScene layout: states learned from its key frames, whatever the frames'
order in transforms.json (docs/data-contract.md, "Key frames and the time axis")."""

from __future__ import annotations

from published_dataset import UNITS, published

from stages.model.trainer import Trainer


def test_training_a_published_dataset_learns_its_states_from_the_key_frames(tmp_path, tiny_config):
    root = published(tmp_path / "ds", blender=True, shuffle=True)
    run = Trainer(tiny_config(root), tmp_path / "run", device="cpu", progress=False).train()
    assert run["state_mode"] == "learned" and set(run["key_frame_ranges"]) == set(UNITS)
    assert "every other frame" in run["split"]
    ordered = Trainer(tiny_config(published(tmp_path / "ds2", blender=True)), tmp_path / "run2", device="cpu",
                      progress=False)
    shuffled = Trainer(tiny_config(root), tmp_path / "run3", device="cpu", progress=False)
    by_time = {round(t, 9): s for t, s in zip(ordered.info.key_times, ordered.info.key_states, strict=True)}
    assert by_time == {round(t, 9): s for t, s in zip(shuffled.info.key_times, shuffled.info.key_states, strict=True)}


def test_a_dataset_whose_frames_carry_states_trains_on_them(tiny_dataset, tmp_path, tiny_config):
    trainer = Trainer(tiny_config(tiny_dataset.root), tmp_path / "run", device="cpu", progress=False)
    assert trainer.config.model.state.mode == "given" and trainer.info.frame_times is None
