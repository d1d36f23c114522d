"""Sphinx configuration of the doefab documentation site (``bash scripts/docs.sh`` builds it).

Markdown pages (MyST), tutorials that run during the build (sphinx-gallery), an API reference from the
docstrings (autodoc, autosummary, napoleon) and pages generated from the repository's own files
(``_ext/doefab_docs.py``: benchmark results, scene keys, command help, the mask manifest).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
# document (and run the tutorials against) this tree, whatever doefab an environment has installed
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS / "_ext"))
os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("TQDM_DISABLE", "1")  # progress bars are for terminals, not for a built page

import doefab  # noqa: E402

project = "doefab"
author = "the doefab authors"
copyright = "the doefab authors, MIT licence"
release = version = doefab.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx_gallery.gen_gallery",
    "doefab_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_generated", "examples/*.md", "**/GALLERY_HEADER.rst", "sg_execution_times.rst"]
templates_path = ["_templates"]

# MyST: fenced directives with ::: too, definition lists, anchors on headings down to level 3 (no math
# extension: MathJax would load from the web, and the site works offline)
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

# API reference: one page per public name, generated from the docstrings
autosummary_generate = True
autosummary_imported_members = True
autodoc_default_options = {"members": True, "member-order": "bysource", "undoc-members": False}
autodoc_typehints = "description"
autodoc_typehints_description_target = "documented_params"
autodoc_class_signature = "separated"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True

# Tutorials: Python scripts in docs/examples, executed on every build, rendered with their figures
sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "tutorials",
    "filename_pattern": r"/plot_",
    "within_subsection_order": "FileNameSortKey",
    "run_stale_examples": os.environ.get("DOEFAB_DOCS_REUSE_TUTORIALS") != "1",
    "abort_on_example_error": False,
    "only_warn_on_example_error": False,
    "download_all_examples": False,
    "remove_config_comments": True,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "show_memory": False,
    "capture_repr": ("_repr_html_",),
    "min_reported_time": 0,
    "write_computation_times": False,  # its page loads scripts from the web; each tutorial states its time
}

html_theme = "pydata_sphinx_theme"
html_title = f"doefab {release}"
html_theme_options = {
    "navigation_depth": 3,
    "show_toc_level": 2,
    "navbar_align": "left",
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
    "secondary_sidebar_items": ["page-toc"],
}
html_sidebars = {"**": ["sidebar-nav-bs"]}
html_show_sourcelink = False
html_copy_source = False
# no web fonts, analytics or other files from outside: the site works offline
html_static_path = ["_static"]
html_css_files = ["doefab.css"]
