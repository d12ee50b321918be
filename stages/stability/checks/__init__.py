"""The stability checks: plain pytest tests that ship with the package.

They are tests (assert, skip, fixtures, parametrize) because that is what they are; they ship inside
``stages.stability`` rather than under ``tests/`` because ``livescene stability`` runs them on an
installed copy too (``stages/stability/suite.py`` runs this folder through ``pytest.main``). One module
per group: ``test_numerics``, ``test_guards``, ``test_bad_input``, ``test_interrupted``; the fixtures,
options and markers are in ``conftest.py``; docs/stability.md describes every check.
"""
