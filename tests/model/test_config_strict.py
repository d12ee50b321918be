"""Model configs are typed: presets, method overlays and --set values are checked against the fields' types."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml
from yaml_round_trip import assert_unchanged

from stages.model import config as config_module
from stages.model.config import METHOD_DIR, PRESET_DIR, RunConfig, config_from_dict, load_config
from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES
from stages.model.train_cli import main as train_main
from stages.scene import InputError

PRESETS = sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))
METHODS = sorted(p.stem for p in METHOD_DIR.glob("*.yaml"))


def refusal(overrides: list[str], preset: str = "cpu-demo") -> InputError:
    with pytest.raises(InputError) as info:
        load_config(preset, overrides)
    return info.value


def test_a_list_with_a_string_in_it_is_refused():
    err = refusal(['model.field.scales=["a",3]'])
    assert err.path == Path("--set")
    assert err.problem == ("'model.field.scales=[\"a\",3]': model.field.scales[0] is 'a' (a string), "
                           "expected an integer")
    assert err.fix == "write model.field.scales as a list of integers, e.g. [1, 2, 4]"


def test_a_number_for_a_choice_is_refused_not_turned_into_text():
    err = refusal(["train.mixed_precision=7"])
    assert err.path == Path("--set") and "train.mixed_precision is 7 (an integer)" in err.problem
    assert "expected one of 'auto', 'bf16', 'fp16', 'off'" in err.problem
    off = refusal(["train.mixed_precision=off"])  # YAML 1.1 reads an unquoted off as false
    assert "is False (a boolean)" in off.problem and "--set \"train.mixed_precision='off'\"" in off.fix
    assert load_config("cpu-demo", ["train.mixed_precision='off'"]).train.mixed_precision == "off"


def test_unknown_keys_name_the_key_path_and_list_the_valid_keys():
    err = refusal(["model.field.channel=8"])
    assert "'model.field.channel=8': model.field has unknown keys ['channel']" in err.problem
    assert "'channels'" in err.fix and "'base_resolution'" in err.fix
    assert "the top level has unknown keys ['bogus']" in refusal(["bogus.x=1"]).problem
    assert "is not key=value" in refusal(["train.max_steps"]).problem


def test_nested_sections_are_dataclasses_and_whole_sections_are_checked():
    cfg = load_config("cpu-demo", ["model.proposal={resolutions: [[8, 4]], hidden: 8}"])
    assert isinstance(cfg.model.proposal, config_module.ProposalConfig)
    assert cfg.model.proposal.resolutions == [[8, 4]] and cfg.model.proposal.hidden == 8
    assert cfg.model.proposal.channels == config_module.ProposalConfig().channels  # the rest: defaults
    assert "model.field is 5 (an integer), expected a mapping of RadianceFieldConfig fields" in refusal(
        ["model.field=5"]).problem
    assert "model.proposal.resolutions[0][1] is 'x'" in refusal(["model.proposal.resolutions=[[8, x]]"]).problem


def test_values_are_typed_exactly():
    cfg = load_config("cpu-demo", ["train.adam_eps=1e-15", "model.probability.rejection_threshold=0",
                                   "train.compile=true"], data=Path("some") / "dataset", seed=3)
    assert cfg.train.adam_eps == 1e-15 and type(cfg.model.probability.rejection_threshold) is float
    assert cfg.train.compile is True and cfg.data == str(Path("some/dataset")) and cfg.seed == 3
    assert "expected an integer" in refusal(["train.max_steps=1000.0"]).problem
    assert "expected true or false" in refusal(["train.compile=1"]).problem
    assert "expected one of 'auto', 'given', 'learned'" in refusal(["model.state.mode=lerned"]).problem
    assert "expected one of 'default', 'reduce-overhead'" in refusal(["train.compile_mode=max-autotune"]).problem


def test_a_bad_preset_or_overlay_value_names_its_file(tmp_path, monkeypatch):
    preset = tmp_path / "mine.yaml"
    preset.write_text("model:\n  field:\n    scales: [1, two]\n")
    with pytest.raises(InputError) as info:
        load_config(str(preset))
    assert info.value.path == preset and "model.field.scales[1] is 'two'" in info.value.problem
    methods = tmp_path / "methods"
    methods.mkdir()
    (methods / "conerf.yaml").write_text("gpu-paper:\n  model:\n    conerf: {hidden: wide}\n")
    monkeypatch.setattr(config_module, "METHOD_DIR", methods)
    with pytest.raises(InputError) as info:
        load_config("gpu-paper", method="conerf")
    assert info.value.path == methods / "conerf.yaml"
    assert "gpu-paper.model.conerf.hidden is 'wide' (a string), expected an integer" in info.value.problem


def _merge(base: dict, overlay: dict) -> None:
    for key, value in overlay.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            _merge(base[key], value)
        else:
            base[key] = value


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("method", [None, *METHODS])
def test_every_preset_and_method_overlay_loads_unchanged(preset, method):
    cfg = load_config(preset, method=method)
    loaded = cfg.to_dict()
    raw = yaml.safe_load((PRESET_DIR / f"{preset}.yaml").read_text()) or {}
    if method:
        overlay = (yaml.safe_load((METHOD_DIR / f"{method}.yaml").read_text()) or {}).get(preset) or {}
        _merge(raw, overlay)  # the overlay wins over the preset
        assert cfg.method == method
    assert_unchanged(raw, loaded, f"{preset}+{method}")
    assert config_from_dict(loaded) == cfg  # what a run folder saves rebuilds the same config
    assert config_from_dict(yaml.safe_load(yaml.safe_dump(loaded))) == cfg
    for section in dataclasses.fields(RunConfig):
        assert type(getattr(cfg, section.name)).__name__ == type(getattr(RunConfig(), section.name)).__name__


def test_the_tiny_overrides_the_tests_use_load():
    cfg = load_config("cpu-demo", [*TINY_MODEL_OVERRIDES, "train.max_steps=4"])
    assert cfg.train.max_steps == 4


def test_train_cli_refuses_a_bad_set_value_with_one_line(tmp_path, capsys):
    args = ["--data", str(tmp_path / "no-dataset"), "--out", str(tmp_path / "run")]
    assert train_main([*args, "--set", 'model.field.scales=["a",3]']) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --set: ") and "model.field.scales[0]" in err and "Traceback" not in err
    assert train_main([*args, "--set", "train.mixed_precision=7"]) == 2
    assert "train.mixed_precision is 7" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(("item", "message"), [
    ("train.batch_rays=0", "train.batch_rays: 0 is out of range"),
    ("train.render_chunk=-5", "train.render_chunk: -5 is out of range"),
    ("train.eval_rays=0", "train.eval_rays: 0 is out of range"),
    ("train.lr=-1", "train.lr: -1.0 is not a finite value in (0, 10]"),
    ("train.lr=1e30", "train.lr: 1e+30 is not a finite value in (0, 10]"),
    ("train.max_seconds=.nan", "train.max_seconds: nan is out of range"),
    ("train.max_steps=0", "train.max_steps: 0 is out of range"),
    ("model.field.base_resolution=0", "model.field.base_resolution: 0 is not at least 1"),
    ("model.field.scales=[]", "model.field.scales: [] is not a list of positive multipliers"),
    ("model.probability.channels=0", "model.probability.channels: 0 is not at least 1"),
    ("model.sampling.num_proposal_samples=[32,16]", "model.sampling.num_proposal_samples: [32, 16] does not give"),
    ("model.sampling.background=[1,1]", "model.sampling.background: [1.0, 1.0] is not an RGB colour"),
    ("model.field.init_range=[0.5,0.1]", "model.field.init_range: [0.5, 0.1] is not [low, high]"),
    ("model.probability.rejection_threshold=1", "model.probability.rejection_threshold: 1.0 is not in [0, 1)"),
    ("model.losses.rgb=-1", "model.losses.rgb: -1.0 is not a finite weight >= 0"),
])
def test_out_of_range_train_values_are_refused_with_the_fix(item, message):
    with pytest.raises(InputError) as info:
        load_config("cpu-demo", [item])
    assert str(info.value).startswith(message) and "fix: give" in str(info.value)


def test_the_train_cli_refuses_a_set_its_options_give_and_an_unknown_device(tmp_path, capsys):
    args = ["--data", str(tmp_path / "no-dataset"), "--out", str(tmp_path / "run")]
    assert train_main([*args, "--set", "preset=gpu-paper"]) == 2  # was recorded as gpu-paper, trained cpu-demo
    assert "fix: pass --preset instead" in capsys.readouterr().err
    assert train_main([*args, "--set", "method=conerf"]) == 2  # was dropped for --method's default
    assert "fix: pass --method instead" in capsys.readouterr().err
    assert train_main([*args, "--device", "gpu"]) == 2
    assert "'gpu' is not a device" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_a_preset_file_takes_the_overlays_of_the_scale_it_names(tmp_path):
    from stages.model.config import PRESET_DIR

    copy = tmp_path / "mypreset.yaml"
    copy.write_text((PRESET_DIR / "cpu-demo.yaml").read_text())
    with pytest.warns(UserWarning, match="trains without its overlay"):
        bare = load_config(str(copy), method="livescene")
    copy.write_text("preset: cpu-demo\n" + (PRESET_DIR / "cpu-demo.yaml").read_text())
    named = load_config(str(copy), method="livescene")
    assert named.to_dict() == load_config("cpu-demo", method="livescene").to_dict()
    assert bare.model.losses.mask_levels != named.model.losses.mask_levels  # the overlay's settings
