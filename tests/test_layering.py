"""The layering of DESIGN.md: algorithm packages never import the simulator."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PURE_PACKAGES = ("semistatic", "robots", "worlds")
FORBIDDEN = {"pybullet", "sim", "scenarios"}


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def importers(package: str, modules: set[str]) -> dict[str, list[str]]:
    """Return the files of ``package`` that import any of ``modules``, with those modules."""
    offenders = {
        str(path.relative_to(ROOT)): sorted(imported_modules(path) & modules)
        for path in sorted((ROOT / package).rglob("*.py"))
    }
    return {name: mods for name, mods in offenders.items() if mods}


@pytest.mark.parametrize("package", PURE_PACKAGES)
def test_pure_packages_do_not_import_pybullet_or_sim(package):
    offenders = importers(package, FORBIDDEN)
    assert offenders == {}, f"only sim/ and scenarios/ may use PyBullet: {offenders}"


def test_semistatic_is_the_lowest_package():
    # robots and worlds import semistatic's types and spec validation; the reverse would
    # make them import each other.
    offenders = importers("semistatic", {"robots", "worlds"})
    assert offenders == {}, f"semistatic must not import robots or worlds: {offenders}"
