"""prompts.yaml keys that YAML reads as something other than the word: `yes:` is the boolean True (refused as
"prompts for unknown objects ['True']", without the fix), `2:` the integer 2, whose synonyms were lost."""

from __future__ import annotations

import pytest
import yaml

from stages.language.vocabulary import ObjectVocabulary
from stages.scene import InputError


def test_a_key_yaml_reads_as_a_boolean_is_refused_with_the_quoting_fix():
    with pytest.raises(InputError, match=r"prompts\.yaml: YAML reads the keys \[True\].*fix: quote the name"):
        ObjectVocabulary.from_prompts(["yes", "drawer"], yaml.safe_load("yes: {synonyms: [box]}\n"))


def test_a_number_key_keeps_its_synonyms():
    vocabulary = ObjectVocabulary.from_prompts(["2", "yes"], yaml.safe_load("2: {synonyms: [second drawer]}\n"
                                                                            "'yes': {synonyms: [box]}\n"))
    assert [e.aliases for e in vocabulary.entries] == [["2", "second drawer"], ["yes", "box"]]
