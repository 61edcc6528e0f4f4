"""MkDocs hook: the committed figures under results/ become files of the site (at
``results/<experiment>/<figure>.png``), so that the pages show them and ``mkdocs build
--strict`` checks every link to one."""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[2]


def on_files(files: Files, config) -> Files:
    for png in sorted((ROOT / "results").glob("*/*.png")):
        files.append(File(str(png.relative_to(ROOT)), str(ROOT), config["site_dir"],
                          config["use_directory_urls"]))
    return files
