"""Sphinx configuration of the tltrack documentation site (``make docs``).

Built with warnings as errors (``-W --keep-going``) and ``nitpicky``: every cross-reference must
resolve. No extension fetches anything: no intersphinx, MathJax from the package
``sphinx-mathjax-offline`` (the SVG output, which needs no font files, so the maths render from
``file://``), and the tutorials run here, from ``examples/tutorials/``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))

project = "tltrack"
author = "the tltrack developers"
copyright = "the tltrack developers"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",
    "sphinx_click",
    "sphinx_gallery.gen_gallery",
    "tltrack_reference",
]
# TLTRACK_DOCS_PROFILE=1 make docs: how long each page took to read
if os.environ.get("TLTRACK_DOCS_PROFILE") == "1":
    extensions.append("sphinx.ext.duration")
# The studies' pages (docs/results/, from papers/<name>/README.md) bring their own link handler.
if (DOCS / "results" / "papers_links.py").exists():
    sys.path.insert(0, str(DOCS / "results"))
    extensions.append("papers_links")

# Markdown pages (myst) and the reStructuredText that sphinx-gallery and the API stubs write.
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
# option names stay ``--flags`` (no en dashes) and quotes stay straight, as in a terminal
smartquotes = False
#: the command's help is Markdown, where `x` is code: in reStructuredText too (sphinx-click)
default_role = "literal"
exclude_patterns = [
    "_build",
    "**/*.ipynb",
    "**/*.py",
    "**/*.zip",
    "**/*.md5",
    "**/*.pickle",
    "**/*.json",
    # the measured results and their reports: the studies' pages (docs/results/, filled by the
    # papers' move) include what they need; the raw folders are data, not pages
    *(["results/*/**"] if (DOCS / "results" / "index.md").exists() else ["results/**"]),
]

myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist", "fieldlist"]
myst_heading_anchors = 3
myst_dmath_double_inline = True

# Every reference must resolve: a broken link, a renamed class or a typo'd role fails the build.
# Without intersphinx (no network), names from outside tltrack (the standard library, NumPy,
# Zenoh, pydantic, Dask, ...) have no page to link to: tltrack_reference.resolve_reference shows
# them as plain text, and resolves every other reference or lets it fail.
nitpicky = True

# every pydantic model's ``model_config``, and each message's ``type`` tag (the wire's reference
# lists the tags), would only repeat themselves
autodoc_default_options = {
    "members": True,
    "show-inheritance": True,
    "exclude-members": "model_config, type",
}
autodoc_member_order = "bysource"
# the sidebar and the page contents list modules, not every class, function and method in them:
# with the objects, every page's navigation tree held thousands of entries, and building it took
# 20 of the site's 70 s (cProfile, furo's _compute_navigation_tree)
toc_object_entries = False
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autodoc_class_signature = "separated"
python_use_unqualified_type_names = True

# MathJax from the package's own copy, SVG output: no CDN, no font files to fetch.
mathjax_path = "mathjax/tex-svg.js"

html_theme = "furo"
html_title = "tltrack"
html_static_path = ["_static"]
html_css_files = ["tltrack.css"]
html_last_updated_fmt = None
html_show_sourcelink = False
html_copy_source = False

sphinx_gallery_conf = {
    "examples_dirs": [str(ROOT / "examples" / "tutorials")],
    "gallery_dirs": ["tutorials/gallery"],
    # only the plot_* scripts run here; the others are run by tests/test_tutorials.py and
    # included in their pages with literalinclude
    "filename_pattern": r"/plot_",
    "ignore_pattern": r"^(?!plot_)",  # matched against the file's name
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "show_memory": False,
    "show_signature": False,
    "capture_repr": (),
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "run_stale_examples": os.environ.get("TLTRACK_DOCS_RERUN") == "1",
    "write_computation_times": False,
}
