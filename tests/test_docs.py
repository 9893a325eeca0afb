"""The documentation: user pages free of project history, the README's promises, the site build.

Most checks read files only. The bundled-scenario check imports ``scenarios``; the example
check runs ``semistatic check``; the site build runs ``mkdocs build --strict`` and is
skipped, with the reason, where MkDocs Material or mkdocstrings is not installed.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
DOCS = ROOT / "docs"
PRODUCT_PACKAGES = ("sim", "robots", "worlds", "semistatic", "scenarios")
README_MAX_LINES = 300

# Words of the project's working history, not of the tool: user pages describe the tool
# as it is (the history is in CHANGELOG.md).
HISTORY_WORDS = re.compile(r"\b(issues?|sessions?|rounds?|mend(?:s|ed|ing)?)\b", re.IGNORECASE)

# Files the repository does not hold: the code must cite its own docs (docs/design.md).
OUTSIDE_FILES = ("../shared", "DESIGN.md", "STYLE.md")

DESIGN_ANCHORS = [f"detail-{n}" for n in range(1, 11)] + [
    "contract-cli",
    "contract-outputs",
    "contract-metrics",
    "contract-api",
    "contract-testbench",
]


def user_pages() -> list[Path]:
    """README.md and every Markdown page under docs/ (the changelog page only includes it)."""
    pages = [README, *sorted(DOCS.rglob("*.md"))]
    return [page for page in pages if page.name.lower() != "changelog.md"]


def product_files() -> list[Path]:
    """Every text file of the five product packages (code, data, URDF)."""
    files = []
    for package in PRODUCT_PACKAGES:
        for path in sorted((ROOT / package).rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix in (
                ".py", ".pyi", ".toml", ".json", ".urdf", ".md", ".txt", ".cfg"
            ):
                files.append(path)
    return files


def readme_section(title: str) -> str:
    """Return the README's text under the ``## title`` heading, up to the next one."""
    text = README.read_text(encoding="utf-8")
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert match, f"README.md has no '## {title}' section"
    return match.group(1)


@pytest.mark.parametrize("page", user_pages(), ids=lambda page: str(page.relative_to(ROOT)))
def test_user_pages_tell_no_project_history(page):
    hits = [
        f"{page.relative_to(ROOT)}:{number}: {match.group(0)!r} in {line.strip()!r}"
        for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1)
        for match in HISTORY_WORDS.finditer(line)
    ]
    assert not hits, "user pages describe the tool, not its history:\n" + "\n".join(hits)


def test_product_code_cites_no_file_outside_the_repository():
    hits = [
        f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
        for path in product_files()
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if any(name in line for name in OUTSIDE_FILES)
    ]
    assert not hits, (
        "cite the repository's own pages (docs/design.md#detail-N, #contract-...) "
        "instead:\n" + "\n".join(hits)
    )


def test_readme_is_the_front_door():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines (at most {README_MAX_LINES}): "
        "move detail to docs/ and history to CHANGELOG.md"
    )


def test_readme_lists_exactly_the_bundled_scenarios():
    from scenarios import bundled_scenarios

    listed = re.findall(r"^\| `([^`]+)` \|", readme_section("Bundled scenarios"), re.M)
    assert sorted(listed) == sorted(bundled_scenarios())
    assert len(listed) == len(set(listed))


def test_readme_links_to_files_that_exist():
    text = README.read_text(encoding="utf-8")
    targets = re.findall(r"\]\(((?!https?://)[^)#\s]+)(?:#[^)]*)?\)", text)
    missing = [target for target in targets if not (ROOT / target).exists()]
    assert targets, "README.md links to no file"
    assert not missing, f"README.md links to missing files: {missing}"


def test_readme_example_is_the_checked_example():
    """The README's world and scenario are docs/examples' files, which the next test checks."""
    blocks = re.findall(r"```toml\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    examples = DOCS / "examples"
    for name in ("first_world.toml", "first_scenario.toml"):
        assert (examples / name).read_text(encoding="utf-8") in blocks, (
            f"README.md's TOML differs from docs/examples/{name}"
        )


@pytest.mark.slow
def test_first_scenario_passes_check():
    result = subprocess.run(
        [sys.executable, "-m", "scenarios", "check", "docs/examples/first_scenario.toml"],
        cwd=ROOT, capture_output=True, text=True, timeout=600, check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "first_scenario: valid" in result.stdout


def test_design_page_keeps_the_anchors_the_code_cites():
    text = (DOCS / "design.md").read_text(encoding="utf-8")
    missing = [anchor for anchor in DESIGN_ANCHORS if f"{{#{anchor}}}" not in text]
    assert not missing, f"docs/design.md lost the anchors {missing}"


def test_api_pages_list_every_public_module():
    """A module added or renamed in the code needs its line on an API page (docs/api/)."""
    listed = set()
    for page in (DOCS / "api").glob("*.md"):
        listed |= set(re.findall(r"^::: ([\w.]+)", page.read_text(encoding="utf-8"), re.M))
    modules = set()
    for package in PRODUCT_PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if not any(part.startswith("_") for part in parts):
                modules.add(".".join(parts))
    unlisted, gone = sorted(modules - listed), sorted(listed - modules)
    assert not unlisted, "add to docs/api/: " + ", ".join(unlisted)
    assert not gone, "gone from the code, drop from docs/api/: " + ", ".join(gone)


def test_design_anchors_the_code_cites_exist():
    text = (DOCS / "design.md").read_text(encoding="utf-8")
    anchors = set(re.findall(r"\{#([\w-]+)\}", text))
    cited = {
        (path.relative_to(ROOT), anchor)
        for path in product_files()
        for anchor in re.findall(r"design\.md#([\w-]+)", path.read_text(encoding="utf-8"))
    }
    missing = sorted(f"{path}: #{anchor}" for path, anchor in cited if anchor not in anchors)
    assert not missing, "docs/design.md has no such anchor:\n" + "\n".join(missing)


def _missing_site_packages() -> list[str]:
    """The packages the site build needs that are not installed."""
    needed = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers")
    return [name for name in needed if importlib.util.find_spec(name) is None]


@pytest.mark.slow
def test_site_builds_strict(tmp_path):
    missing = _missing_site_packages()
    if missing:
        pytest.skip(
            f"the docs site needs {', '.join(missing)}: "
            "pip install 'mkdocs-material>=9.5' 'mkdocstrings[python]>=0.26'"
        )
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet",
         "--config-file", str(ROOT / "mkdocs.yml"), "--site-dir", str(tmp_path / "site")],
        cwd=ROOT, capture_output=True, text=True, timeout=900, check=False,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert result.returncode == 0, (result.stdout + result.stderr)[-6000:]
    assert (tmp_path / "site" / "design" / "index.html").is_file()
