"""Sphinx configuration of the documentation site (``make docs``; MyST Markdown pages).

The API reference is generated from the docstrings (autosummary over the package names, so a new
module or subpackage appears by itself), the CLI reference from ``exo-ilc``'s argparse parser
(sphinx-argparse). ``make docs`` builds with warnings as errors.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the checkout's package, also without an install
sys.path.insert(0, str(HERE / "_ext"))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # autodoc imports the nodes
os.environ.setdefault("MPLBACKEND", "Agg")

# The API pages are generated on every build: stale ones (a module moved or renamed) would
# document what no longer exists.
shutil.rmtree(HERE / "api", ignore_errors=True)

project = "exo_ilc_ros"
author = "exo_ilc_ros developers"
copyright = "exo_ilc_ros developers, Apache-2.0"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinxarg.ext",
    "exo_ilc_docs",  # docs/_ext: |e| in docstrings and in the CLI's help
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build"]
templates_path = ["_templates"]

myst_heading_anchors = 3  # `[x](page.md#a-heading)` works here as on GitHub
myst_enable_extensions = ["colon_fence"]

autosummary_generate = True
autosummary_ignore_module_all = False  # a package's page documents its __all__ (its face)
autosummary_imported_members = False


def package_faces(root: str = "exo_ilc_ros") -> list[str]:
    """The packages with ``__all__`` (``exo_ilc_ros.core``, ``exo_ilc_ros.bag``): faces. A face's
    page documents those names and lists its modules and subpackages without a page each (their
    paths may move; the face stays). A package without one gets a page per module."""
    package = importlib.import_module(root)
    names = [root] + [info.name for info in pkgutil.walk_packages(package.__path__, root + ".")
                      if info.ispkg]
    faces = [name for name in names if hasattr(importlib.import_module(name), "__all__")]
    for name in faces:  # a face that loads its names lazily (PEP 562) has them all loaded now
        module = importlib.import_module(name)
        for member in module.__all__:
            getattr(module, member)
    return sorted(faces)


autosummary_context = {"faces": package_faces()}
autodoc_member_order = "bysource"
autodoc_typehints = "description"

html_theme = "furo"
html_title = "exo_ilc_ros"
html_static_path: list[str] = []
html_show_sourcelink = False
smartquotes = False  # "--config" stays two hyphens, quotes stay as typed
highlight_language = "text"  # a fence without a language is shown as typed

