"""Sphinx configuration of the dvr_gl documentation.

Build (afresh, warnings as errors, as scripts/test.sh builds it):

    python -m sphinx -E -W --keep-going -b html docs docs/_build/html

The build needs no network: no intersphinx inventories, no remote images, and the
theme's links all point into the site itself. The gallery (examples/plot_*.py) runs each
script headless, rendering with dvr_gl's own EGL (else OSMesa) context, and collects the
matplotlib figures it draws.
"""

import os
import sys

os.environ.setdefault("MPLBACKEND", "Agg")      # headless: the gallery's figures are scraped, never shown

import matplotlib

matplotlib.use("Agg")

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))       # the checkout's dvr_gl, installed or not

import dvr_gl

# -- Project ---------------------------------------------------------------------------

project = "dvr_gl"
author = "the dvr_gl authors"
copyright = "the dvr_gl authors"
version = dvr_gl.__version__
release = dvr_gl.__version__

# -- General ---------------------------------------------------------------------------

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
templates_path = ["api/_templates"]
# Build outputs only: every page of the source tree is part of the site.
exclude_patterns = ["_build"]
pygments_style = "sphinx"
default_role = "literal"        # `x` in reST docstrings is code, as in the Markdown pages

# -- MyST (the Markdown pages) ---------------------------------------------------------

myst_enable_extensions = [
    "amsmath",
    "colon_fence",
    "deflist",
    "dollarmath",
    "smartquotes",
    "strikethrough",
    "tasklist",
]
myst_heading_anchors = 4        # `[text](page.md#a-heading)` links to headings
myst_dmath_double_inline = True

# -- API reference: autodoc, autosummary, numpydoc -------------------------------------

autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "none"      # the signatures show the parameters; numpydoc the types
autodoc_preserve_defaults = True
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks = set()  # no docstring style validation
numpydoc_xref_param_type = False

# -- Example gallery -------------------------------------------------------------------

sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": "/plot_",
    "image_scrapers": ("matplotlib",),
    "within_subsection_order": "FileNameSortKey",   # plot_01_..., plot_02_...: the reading order
    "download_all_examples": False,
    "remove_config_comments": True,
    "show_memory": False,
    "matplotlib_animations": False,
    "reference_url": {"dvr_gl": None},      # link names in the code to this site's API pages
    "capture_repr": (),                     # the pictures are the output, not the last value's repr
}

# -- HTML ------------------------------------------------------------------------------

html_theme = "pydata_sphinx_theme"
html_title = f"dvr_gl {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "navbar_align": "left",
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
    "secondary_sidebar_items": ["page-toc"],
}
html_show_sourcelink = False
html_static_path = []


# -- Checks ----------------------------------------------------------------------------

def _check_model_modules(app):
    """Warn when a public module of dvr_gl.model is missing from api/model.rst's list."""
    import pkgutil

    import dvr_gl.model
    from sphinx.util import logging

    with open(os.path.join(app.srcdir, "api", "model.rst"), encoding="utf-8") as f:
        page = f.read()
    for module in pkgutil.iter_modules(dvr_gl.model.__path__):
        if not module.name.startswith("_") and f"\n   {module.name}\n" not in page:
            logging.getLogger(__name__).warning(f"dvr_gl.model.{module.name} is not listed in api/model.rst",
                                                location="api/model")


def setup(app):
    app.connect("builder-inited", _check_model_modules)
