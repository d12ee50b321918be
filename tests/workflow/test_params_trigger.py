"""Every setting a rule's command carries is in Snakemake's params trigger, so changing it reruns the rule.

Snakemake leaves a params function that takes ``input``, ``output``, ``threads`` or ``resources`` out of the
trigger (it counts as derived from them): a sheet's ``state_ranges`` or config ``train.appearance`` computed
that way changed the command of the next run and never reran the last one. Param functions therefore take the
wildcards alone and read the rule's input function themselves; only those that merely name an input or output
path (which the input/output triggers already cover) may take ``input`` or ``output``.
"""

from __future__ import annotations

import re
from pathlib import Path

RULES = Path(__file__).resolve().parents[2] / "workflow" / "rules"
# name -> why it may derive from the rule's files: it only spells a path the file triggers already watch
DERIVED_OK = {
    "run_folder": "the run folder of the run.json input",
    "frames_video": "the video file of the frames input",
    "report_manifest": "the report's inputs by role, nothing else",
}


def _functions() -> dict[str, list[str]]:
    """Every function of the rule files with its parameter names."""
    out = {}
    for path in RULES.glob("*.smk"):
        for m in re.finditer(r"^def (\w+)\(([^)]*)\)", path.read_text(), re.M):
            out[m.group(1)] = [p.split(":")[0].split("=")[0].strip() for p in m.group(2).split(",") if p.strip()]
    return out


def _params_entries() -> list[tuple[str, str, str]]:
    """(file, rule, value text) of every ``params:`` entry of every rule."""
    out = []
    for path in RULES.glob("*.smk"):
        rule = None
        in_params = False
        for line in path.read_text().splitlines():
            if m := re.match(r"^(?:rule|checkpoint) (\w+):", line):
                rule, in_params = m.group(1), False
            elif re.match(r"^    params:\s*$", line):
                in_params = True
            elif in_params and re.match(r"^    \w", line):
                in_params = False
            elif in_params and (m := re.match(r"^        \w+\s*=\s*(.+)$", line)):
                out.append((path.name, rule or "?", m.group(1)))
    return out


def test_no_rule_setting_escapes_the_params_trigger():
    functions = _functions()
    entries = _params_entries()
    assert len(entries) > 30, "no params entries found: has the rule files' layout changed?"
    derived = []
    for file, rule, value in entries:
        if re.match(r"lambda\s+[\w\s,]*\b(input|threads|resources)\b", value):
            derived.append(f"{file} rule {rule}: {value}")
        name = re.match(r"(\w+),?$", value.strip())
        if name and name.group(1) in functions:
            taken = set(functions[name.group(1)][1:])
            if taken & {"input", "output", "threads", "resources"} and name.group(1) not in DERIVED_OK:
                derived.append(f"{file} rule {rule}: {name.group(1)}{tuple(functions[name.group(1)])}")
    assert not derived, "params Snakemake would not rerun on (take the wildcards alone):\n" + "\n".join(derived)


def _params_blocks() -> dict[str, str]:
    """rule -> the text of its ``params:`` block."""
    out = {}
    for path in RULES.glob("*.smk"):
        for m in re.finditer(r"^(?:rule|checkpoint) (\w+):\n(.*?)(?=^(?:rule|checkpoint) |\Z)", path.read_text(),
                             re.M | re.S):
            block = re.search(r"^    params:\n(.*?)(?=^    \w)", m.group(2), re.M | re.S)
            if block:
                out[m.group(1)] = block.group(1)
    return out


def test_a_rule_with_several_settings_names_them_in_one_param():
    """Snakemake compares params as a set of values without names: with ``max_views`` and ``max_locality_pairs``
    as two params, 1 -> 40 beside 40 changed nothing it compares. Every config value such a rule carries is also
    in its ``settings=named(...)`` param, which any change changes."""
    setting = r"config(?:\[\"\w+\"\])+"
    missing = []
    for rule, text in _params_blocks().items():
        entries = re.split(r"^        (?=\w+\s*=)", text, flags=re.M)  # one entry with its continuation lines
        named = "".join(e for e in entries if re.match(r"\w+\s*=\s*named\(", e))
        loose = [set(re.findall(setting, e)) for e in entries if e and not re.match(r"\w+\s*=\s*named\(", e)]
        loose = [refs for refs in loose if refs]
        if len(loose) < 2:  # one param can only change as a whole
            continue
        missing += [f"{rule}: {key}" for key in sorted(set().union(*loose) - set(re.findall(setting, named)))]
    assert not missing, "settings outside the rule's named(...) param:\n" + "\n".join(missing)
