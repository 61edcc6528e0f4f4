"""The docs site's sources (mkdocs.yml, docs/): every page in the navigation, a page for every
command, API references that resolve to documented objects, and nothing pointing outside
the repository. (``mkdocs build --strict`` in CI checks the rendered links and runs the
tutorial; these checks need no docs packages.)"""

import importlib
import re
from pathlib import Path

import yaml

from bounce_cli.experiments.registry import EXPERIMENTS

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def nav_pages(nav) -> list[str]:
    pages = []
    for item in nav:
        if isinstance(item, str):
            pages.append(item)
        else:
            for value in item.values():
                pages += nav_pages(value) if isinstance(value, list) else [value]
    return pages


def test_every_page_is_in_the_navigation_and_every_command_has_one():
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    listed = nav_pages(config["nav"])
    on_disk = sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*")
                     if p.suffix in (".md", ".py") and "hooks" not in p.parts)
    assert sorted(listed) == on_disk
    assert len(set(listed)) == len(listed)
    # study is the start of the data workflow's page; every other command has its own
    commands = {e.name for e in EXPERIMENTS} - {"study", "simulate-study"} | {
        "fixed-point", "orbit", "reproduce", "verify"}
    missing = sorted(c for c in commands if f"commands/{c}.md" not in listed
                     and not c.endswith("-data"))
    assert missing == []


def test_api_references_resolve_to_documented_objects():
    page = (DOCS / "api.md").read_text()
    references = re.findall(r"^::: ([\w.]+)$", page, flags=re.M)
    assert "bounce_cli.api.run" in references and len(references) >= 10
    for reference in references:
        module_name, _, name = reference.rpartition(".")
        obj = getattr(importlib.import_module(module_name), name)
        assert (obj.__doc__ or "").strip(), f"{reference} has no docstring"


def test_nothing_points_outside_the_repository():
    texts = [p for p in [ROOT / "README.md", ROOT / "CHANGELOG.md", ROOT / "mkdocs.yml",
                         *DOCS.rglob("*.md"), *DOCS.rglob("*.py")]]
    for path in texts:
        text = path.read_text()
        for needle in ("/work/", "../shared", "shared/paper", "DESIGN.md"):
            assert needle not in text, (path, needle)
