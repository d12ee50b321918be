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


def test_a_run_finds_its_frames_by_id_in_a_dataset_given_in_another_order(tmp_path, tiny_config):
    """evaluate and relevancy took a frame's position in --data: a re-ordered copy gave other frames' states."""
    from stages.model import load_run
    from stages.scene import read_scene

    root = published(tmp_path / "ds", shuffle=True)
    Trainer(tiny_config(root), tmp_path / "run", device="cpu", progress=False).train()
    run = load_run(tmp_path / "run", device="cpu")
    ds = read_scene(root)
    reordered = sorted(ds.frames, key=lambda f: f.frame_id)
    for frame in reordered:
        assert run.frame_index_of(frame, reordered) == ds.frames.index(frame)
    stranger = type(ds.frames[0])(file_path="images/frame_99999.png", c2w=ds.frames[0].c2w)
    assert run.frame_index_of(stranger, reordered) is None
