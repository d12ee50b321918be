"""One way to build a method's config: preset + the method's overlay + explicit overrides, for every caller."""

from __future__ import annotations

import yaml

from stages.compare.method_comparison import ALL_METHODS, method_preset
from stages.model import load_config
from stages.model.config import METHOD_DIR


def test_overlay_applies_whichever_way_the_method_is_named():
    overlay = yaml.safe_load((METHOD_DIR / "conerf.yaml").read_text())["gpu-paper"]["model"]["conerf"]
    by_field = load_config("gpu-paper", method="conerf").model.conerf
    by_override = load_config("gpu-paper", ["method=conerf"]).model.conerf
    for cfg in (by_field, by_override):
        assert (cfg.hidden, cfg.hidden_layers, cfg.attribute_frequencies) == (
            overlay["hidden"], overlay["hidden_layers"], overlay["attribute_frequencies"])
    base = load_config("gpu-paper", method="livescene").model.conerf  # the overlay belongs to conerf only
    assert (base.hidden, base.attribute_frequencies) != (overlay["hidden"], overlay["attribute_frequencies"])


def test_explicit_overrides_win_over_the_overlay():
    cfg = load_config("gpu-paper", ["model.conerf.hidden=32"], method="conerf")
    assert cfg.model.conerf.hidden == 32


def test_workflow_and_compare_train_the_same_config():
    for method in ALL_METHODS:
        for scale in ("cpu-demo", "gpu-paper"):
            trained = load_config(scale, method=method).to_dict()  # what `livescene train --method` builds
            compared = method_preset(method, scale)  # what `livescene compare` trains
            assert compared["model"] == trained["model"] and compared["train"] == trained["train"], (method, scale)


def test_livescene_alone_reads_no_state_in_its_probability_field_at_cpu_demo():
    """LiveScene's cpu-demo overlay (docs/model.md, "Locality and the probability field's state input")."""
    assert load_config("cpu-demo", method="livescene").model.probability.state_input == "none"
    assert load_config("gpu-paper", method="livescene").model.probability.state_input == "all"  # the reference
    for method in ("mk-planes", "conerf"):
        assert load_config("cpu-demo", method=method).model.probability.state_input == "all"


def test_livescene_alone_adds_the_rendered_probabilities_to_its_mask_loss_at_cpu_demo():
    """LiveScene's cpu-demo overlay (docs/model.md, "The mask loss on rendered probabilities")."""
    assert load_config("cpu-demo", method="livescene").model.losses.focal_mask_on == "both"
    assert load_config("gpu-paper", method="livescene").model.losses.focal_mask_on == "logits"  # the reference
    for method in ("mk-planes", "conerf"):
        assert load_config("cpu-demo", method=method).model.losses.focal_mask_on == "logits"


def test_livescene_alone_keeps_its_mask_losses_to_the_final_level_at_cpu_demo():
    """LiveScene's cpu-demo overlay (docs/model.md, "The mask losses at the final level")."""
    assert load_config("cpu-demo", method="livescene").model.losses.mask_levels == "final"
    assert load_config("gpu-paper", method="livescene").model.losses.mask_levels == "all"  # the reference
    for method in ("mk-planes", "conerf"):
        assert load_config("cpu-demo", method=method).model.losses.mask_levels == "all"


def test_a_config_without_a_method_is_the_default_methods_with_its_overlay():
    assert load_config("cpu-demo").to_dict() == load_config("cpu-demo", method="livescene").to_dict()
