"""Sphinx extension: the links of a study's README, included by its page, that lead out of the site.

Each page of ``docs/results/`` includes ``papers/<name>/README.md`` (and papers/README.md), which
are written for GitHub: their links are relative to the paper's folder. The pages' ``{include}``
rewrites them relative to the page (``:relative-docs: .``), which serves the docs and files a
paper links to; this handler ("include-read") first points what the site shows as pages at those
pages, and what it cannot show at a download:

- another paper's README (``../rpf/README.md#anchor``): that paper's page, ``/results/rpf.md``;
- papers/README.md: the results' index, ``/results/index.md``;
- any other Markdown file outside ``docs/`` (a results table, benchmarks/README.md): a download
  (``path:``), as Sphinx would otherwise take it for a page it does not have.

Registered by conf.py: ``sys.path`` holds ``docs/results``, and ``extensions`` names this module.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

LINK = re.compile(r"(\]\()([^)\s]+)(\))")
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def rewrite(text: str, source: Path, srcdir: Path, papers: Path) -> str:
    """``text`` of ``source`` (a file under ``papers``) with its links out of the site pointed at
    the results' pages or made downloads."""

    def one(m: re.Match[str]) -> str:
        target = m.group(2)
        if target.startswith("#") or SCHEME.match(target):
            return m.group(0)
        path, hash_, anchor = target.partition("#")
        dest = (source.parent / path).resolve()
        if dest.suffix != ".md" or dest.is_relative_to(srcdir):
            return m.group(0)
        if dest == papers / "README.md":
            new = "/results/index.md" + hash_ + anchor
        elif dest.name == "README.md" and dest.parent.parent == papers:
            new = f"/results/{dest.parent.name}.md" + hash_ + anchor
        else:
            new = "path:" + path
        return m.group(1) + new + m.group(3)

    return LINK.sub(one, text)


def on_include_read(app: Any, relative_path: Path, parent_docname: str, content: list[str]) -> None:
    srcdir = Path(app.srcdir).resolve()
    papers = (srcdir.parent / "papers").resolve()
    source = (srcdir / relative_path).resolve()
    if source.is_relative_to(papers):
        content[0] = rewrite(content[0], source, srcdir, papers)


def setup(app: Any) -> dict[str, Any]:
    app.connect("include-read", on_include_read)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
