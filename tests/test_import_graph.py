"""No stage package imports one that comes after it in the "Stage order" of docs/data-contract.md.

The modules are parsed with ``ast``, never imported, so the check is fast and sees every import: top-level,
inside functions (imported on use), under ``TYPE_CHECKING``, absolute or relative.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STAGES = ROOT / "stages"
DOC = ROOT / "docs" / "data-contract.md"


@dataclass(frozen=True)
class StageImport:
    """One import of a stage package by a module of another one."""

    module: str
    """Dotted name of the importing module (``stages.scene.cli``)."""
    line: int
    source: str
    """Package of the importing module ("" for ``stages/__init__.py``)."""
    target: str
    """Imported package."""


def stage_order(text: str) -> list[str]:
    """The packages of the "## Stage order" section, in order: its lines ``N. `package` ...``."""
    section = re.search(r"^## Stage order\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert section, "docs/data-contract.md has no '## Stage order' section"
    order = re.findall(r"^\d+\. `(\w+)`", section.group(1), re.M)
    assert order, "the 'Stage order' section lists no package (lines '1. `scene` ...')"
    return order


def package_of(module: str) -> str:
    """``stages.x.y`` -> ``x``; ``stages.cli`` -> ``cli``; ``stages`` -> ""."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def stage_imports(module: str, source: str, is_package: bool = False) -> list[StageImport]:
    """The imports of other stage packages in one module's source (``is_package``: it is an ``__init__``)."""
    own = package_of(module)
    found: set[tuple[int, str]] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = module.split(".") if is_package else module.split(".")[:-1]
                if node.level - 1 >= len(anchor):
                    raise ValueError(f"{module}:{node.lineno}: relative import beyond the top package")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            # `from stages import scene` and `from .. import scene` name the package in the imported names
            names = [base, *(f"{base}.{alias.name}" for alias in node.names)]
        else:
            continue
        for name in names:
            parts = name.split(".")
            if parts[0] == "stages" and len(parts) > 1 and parts[1] != own:
                found.add((node.lineno, parts[1]))
    return [StageImport(module, line, own, target) for line, target in sorted(found)]


def upstream_imports(imports: list[StageImport], order: list[str]) -> list[StageImport]:
    """The imports of a package listed after the importing one (``stages/__init__.py`` may import none)."""
    rank = {name: i for i, name in enumerate(order)}
    return [imp for imp in imports if rank.get(imp.source, -1) < rank.get(imp.target, len(order))]


def stage_modules() -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package's ``__init__``) for every module under stages/."""
    out = {}
    for path in sorted(STAGES.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        is_package = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def all_stage_imports() -> list[StageImport]:
    return [imp for module, (path, is_package) in stage_modules().items()
            for imp in stage_imports(module, path.read_text(), is_package)]


def describe(imports: list[StageImport]) -> str:
    return "\n".join(f"  {imp.module} (line {imp.line}) imports stages.{imp.target}" for imp in imports)


def test_the_stage_order_lists_every_package_once():
    order = stage_order(DOC.read_text())
    packages = {package_of(m) for m in stage_modules()} - {""}
    assert len(order) == len(set(order)), f"a package is listed twice: {order}"
    assert set(order) == packages, (f"docs/data-contract.md 'Stage order' lacks {sorted(packages - set(order))} "
                                    f"and lists {sorted(set(order) - packages)}, which stages/ does not have")
    assert order[0] == "scene", "the shared contract package comes first: every stage imports it"


def test_no_stage_imports_a_later_one():
    order = stage_order(DOC.read_text())
    bad = upstream_imports(all_stage_imports(), order)
    assert not bad, ("imports running upstream against docs/data-contract.md 'Stage order' "
                     f"({' < '.join(order)}):\n{describe(bad)}")


def test_the_contract_package_imports_no_stage():
    bad = [imp for imp in all_stage_imports() if imp.source == "scene"]
    assert not bad, f"stages.scene is the shared contract and may import no stage package:\n{describe(bad)}"


def test_the_checker_flags_upstream_imports_in_every_form():
    order = ["scene", "states", "model", "language"]
    sources = {
        ("stages.scene.bad_absolute", False): "from stages.states import read_states_csv\n",
        ("stages.scene.bad_relative", False): "def f():\n    from ..model.run import load_run\n",
        ("stages.scene", True): "from .camera import Camera\nfrom .. import language\n",
        ("stages.model.bad_plain", False): "import stages.language.cli\n",
        ("stages.model.ok", False): "from stages.scene import Camera\nfrom . import run\nfrom .run import load_run\n",
        ("stages.language.ok", False): "from stages import model\nfrom ..scene import InputError\nimport numpy\n",
    }
    imports = [imp for (module, is_package), text in sources.items()
               for imp in stage_imports(module, text, is_package)]
    flagged = {(imp.module, imp.line, imp.target) for imp in upstream_imports(imports, order)}
    assert flagged == {("stages.scene.bad_absolute", 1, "states"), ("stages.scene.bad_relative", 2, "model"),
                       ("stages.scene", 2, "language"), ("stages.model.bad_plain", 1, "language")}
    assert {(imp.module, imp.target) for imp in imports if imp.module.endswith(".ok")} == {
        ("stages.model.ok", "scene"), ("stages.language.ok", "model"), ("stages.language.ok", "scene")}
    with pytest.raises(ValueError, match="beyond the top package"):
        stage_imports("stages.scene.x", "from ... import y\n")


def test_the_order_is_read_from_the_doc_section():
    text = "# t\n## Stage order\nprose\n\n1. `scene` - contract\n2. `model` - x\n\n## Later\n3. `not_read`\n"
    assert stage_order(text) == ["scene", "model"]
