"""The layering of docs/design.md: algorithm packages never import the simulator."""

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


# The wings of scenarios/, lowest first: each imports only the wings before it.
WINGS = ("process", "spec", "bench", "results", "logs", "tuning", "campaign", "falsify",
         "commands")
SCENARIOS_TOP_LEVEL = {"__init__.py", "__main__.py", "cli.py", "data"}
MAX_MODULE_LINES = 450


def scenario_modules():
    return sorted((ROOT / "scenarios").rglob("*.py"))


def imported_names(path: Path) -> set[str]:
    """Every module a file imports, dotted in full (``from a.b import c``: ``a.b``, ``a.b.c``)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def test_scenarios_top_level_holds_only_the_door_the_cli_and_the_data():
    entries = {path.name for path in (ROOT / "scenarios").iterdir()
               if path.name != "__pycache__"}
    assert entries - SCENARIOS_TOP_LEVEL <= set(WINGS), entries - SCENARIOS_TOP_LEVEL
    for wing in WINGS:
        doc = ast.get_docstring(ast.parse((ROOT / "scenarios" / wing / "__init__.py").read_text()))
        assert doc, f"scenarios/{wing} needs a one-line docstring of its job"
        assert "\n" not in doc.strip(), f"scenarios/{wing}: one line"


@pytest.mark.parametrize("wing", WINGS)
def test_a_wing_imports_only_the_wings_below_it(wing):
    allowed = {f"scenarios.{lower}" for lower in WINGS[:WINGS.index(wing) + 1]}
    offenders = {}
    for path in sorted((ROOT / "scenarios" / wing).rglob("*.py")):
        wrong = sorted(name for name in imported_names(path)
                       if name.startswith("scenarios.") and len(name.split(".")) > 2
                       and ".".join(name.split(".")[:2]) not in allowed)
        if wrong:
            offenders[str(path.relative_to(ROOT))] = wrong
    assert offenders == {}, f"scenarios/{wing} imports a higher wing or the CLI: {offenders}"


def test_no_module_imports_itself_back_through_others():
    graph = {}
    for path in scenario_modules():
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        graph[module] = {name for name in imported_names(path) if name.startswith("scenarios.")}
    modules = set(graph)
    edges = {module: {name for name in names if name in modules and name != module}
             for module, names in graph.items()}
    # Depth-first search for a cycle among module-level imports.
    state: dict[str, int] = {}

    def visit(module, trail):
        state[module] = 1
        for nxt in edges[module]:
            if state.get(nxt) == 1:
                raise AssertionError("import circle: " + " -> ".join([*trail, module, nxt]))
            if nxt not in state:
                visit(nxt, [*trail, module])
        state[module] = 2

    for module in sorted(edges):
        if module not in state:
            visit(module, [])


def test_no_module_under_scenarios_is_longer_than_the_limit():
    long = {str(path.relative_to(ROOT)): n for path in scenario_modules()
            if (n := len(path.read_text().splitlines())) > MAX_MODULE_LINES}
    assert long == {}, f"split these modules (> {MAX_MODULE_LINES} lines): {long}"


PRODUCT_PACKAGES = ("sim", "robots", "worlds", "semistatic", "scenarios")


def python_files(*folders):
    for folder in folders:
        yield from sorted((ROOT / folder).rglob("*.py"))


def is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_uses(path: Path) -> list[str]:
    """Private names of other modules a file imports, or reads as ``module[.sub]._name``.

    Relative imports count as the project's own (``from .merge import _x`` too).
    """
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    modules = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.level or (
                node.module and
                node.module.split(".")[0] in (*PRODUCT_PACKAGES, "tests", "benchmarks"))):
            source = "." * node.level + (node.module or "")
            found += [f"from {source} import {alias.name}" for alias in node.names
                      if is_private(alias.name)]
            if any(is_private(part) for part in (node.module or "").split(".")):
                found.append(f"from {source} import ...")
            modules.update(alias.asname or alias.name for alias in node.names)
        elif isinstance(node, ast.Import):
            modules.update(alias.asname or alias.name.split(".")[0] for alias in node.names
                           if alias.name.split(".")[0] in PRODUCT_PACKAGES)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and is_private(node.attr):
            root = node.value  # the name a chain such as semistatic.merge._x starts from
            while isinstance(root, ast.Attribute):
                root = root.value
            if isinstance(root, ast.Name) and root.id in modules:
                found.append(ast.unparse(node))
    return found


def test_no_product_module_uses_another_modules_private_names():
    offenders = {str(path.relative_to(ROOT)): uses for path in python_files(*PRODUCT_PACKAGES)
                 if (uses := private_uses(path))}
    assert offenders == {}, f"make these public in the lower module: {offenders}"


def test_no_test_imports_a_private_name():
    offenders = {str(path.relative_to(ROOT)): uses
                 for path in python_files("tests", "benchmarks", "examples")
                 if (uses := [use for use in private_uses(path) if use.startswith("from ")])}
    assert offenders == {}, f"test the public face instead: {offenders}"


def test_observers_and_policies_are_called_through_their_written_hooks():
    probes = ("hasattr(bench", "getattr(self.policy", "getattr(policy")
    offenders = [f"{path.relative_to(ROOT)}: {probe}" for path in python_files(*PRODUCT_PACKAGES)
                 for probe in probes if probe in path.read_text()]
    assert offenders == []
