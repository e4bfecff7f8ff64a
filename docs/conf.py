"""Sphinx configuration of the toolkit's documentation site.

Build it with ``python3 tasks.py docs`` (HTML in ``out/docs/``): that stages these pages, the
notebooks (as ``tutorials/``) and the generated command-line reference in one folder
(``docs/_ext/site.py``) and runs Sphinx on it with this file, every warning an error and every
unresolved reference a warning (nitpicky).
"""

from __future__ import annotations

import importlib
import logging
import types
from importlib.metadata import version as _installed_version
from pathlib import Path



project = "tractor-autosteer"
author = "tractor-autosteer developers"
copyright = "the tractor-autosteer developers, MIT licence"
release = version = _installed_version("tractor-autosteer")

extensions = [
    "myst_nb",                      # Markdown pages and the notebooks (MyST + jupytext)
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx.ext.mathjax",
]

templates_path = [str(Path(__file__).resolve().parent / "_templates")]   # absolute: the sources are staged elsewhere
exclude_patterns = ["**/__pycache__", "**/.ipynb_checkpoints",
                    "calibration/previous"]   # earlier calibrations' reports, kept as data beside the current one
root_doc = "index"

# Pages are Markdown (the generated API pages reStructuredText); the tutorials are the percent-format notebooks, read through jupytext.
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".py": "myst-nb"}
nb_custom_formats = {".py": ["jupytext.reads", {"fmt": "py:percent"}]}
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 4            # [text](page.md#a-heading) links resolve to the heading's slug

# Notebook outputs: executed once and cached (jupyter-cache); the build passes the mode and the
# cache's folder (-D nb_execution_mode=cache|off, -D nb_execution_cache_path=...).
nb_execution_mode = "off"
nb_execution_cache_path = ""
nb_execution_timeout = 900
nb_execution_in_temp = True         # the notebooks write nb_out/ in their working directory
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True

# API reference: one page per module (docs/_templates/autosummary/module.rst), from the numpydoc
# docstrings; members in source order, only what the module defines.
autosummary_generate = True
toc_object_entries = False          # tables of contents list sections, not every object (with them, the navigation
                                    # tree that the theme computes for each of the ~300 pages took most of the build)
autosummary_imported_members = False
autodoc_member_order = "bysource"
autodoc_typehints = "none"          # the numpydoc sections carry the types, with their units
autodoc_default_options = {"members": True, "undoc-members": True, "show-inheritance": True,
                           "ignore-module-all": True}   # a module documents what it defines, not what it re-exports
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()

# Nitpicky (the build passes -n): every reference must resolve, except to the standard library and the
# third-party packages, whose inventories are not fetched (the build runs offline).
nitpick_ignore_regex = [
    (r"py:.*", r"(.*\.)?_[A-Za-z].*"),         # private names (a private base class, a private helper)
    (r"py:.*", r"(numpy|np|scipy|pathlib|typing|collections|argparse|datetime|enum|io|os|json|socket|"
               r"serial|can|cvxpy|casadi|control|matplotlib|concurrent|threading|asyncio|dataclasses|"
               r"subprocess|abc|types|re|jinja2|dask|distributed|cryptography)\..*"),
]

smartquotes_action = "qe"           # quotes and ellipses; "--option" stays two hyphens

html_theme = "furo"
html_title = f"tractor-autosteer {release}"
html_static_path: list[str] = []
html_copy_source = False
html_show_sourcelink = False


class _EmptyGuidesGlob(logging.Filter):
    """Lets the how-to guides' toctree glob (``guides/*``) match nothing: the folder is where new guides
    go and may be empty; every other empty glob stays a warning (an error in the build)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not ("didn't match any documents" in str(record.msg) and record.args == ("guides/*",))


#: The toolkit's packages: the API reference documents what they define.
PACKAGES = ("autosteer", "gnss", "identification", "design", "hil")


def _skip_member(app, what, name, obj, skip, options) -> bool | None:
    """Leave out of a module's page a type alias (``Row = tuple[float, ...]``: on Python 3.11 it passes for
    a class that autodoc then fails to document) and a class or function of another package that the
    module imports; a reference to either is shown without a link (:func:`_resolve_as_python_does`)."""
    if isinstance(obj, types.GenericAlias):
        return True
    module = getattr(obj, "__module__", None)
    if isinstance(obj, type | types.FunctionType | types.BuiltinFunctionType) and isinstance(module, str) \
            and module.split(".")[0] not in PACKAGES:
        return True
    return None


def _find_object(path: str) -> tuple[str, object] | None:
    """The object that the dotted ``path`` names (its longest importable module, then attributes), with the
    path; None when there is none."""
    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for name in parts[i:]:
                obj = getattr(obj, name)
        except AttributeError:
            return None
        return path, obj
    return None


def _canonical(path: str, obj: object) -> str:
    """Where ``obj`` is defined (``module.qualname``) when it says so, else the path it was found by."""
    if isinstance(obj, types.ModuleType):
        return obj.__name__
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return f"{module}.{qualname}" if isinstance(module, str) and isinstance(qualname, str) else path


def _resolve_as_python_does(app, env, node, contnode):
    """Resolve a Python reference that Sphinx did not find the way Python would read it in the docstring's
    module (``ArcPath`` in a module that imports it, ``Model.fit``, ``pyubx2``): link to where the object is
    documented; an object that exists but is not documented (a constant, another package) is shown without
    a link; a short name that is neither (``poll`` in a module's prose) links to the one documented object
    whose full name ends with it. Anything else stays a warning (an error in the build)."""
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip(".~")
    modname, clsname = node.get("py:module"), node.get("py:class")
    candidates = [f"{modname}.{clsname}.{target}" if modname and clsname else None,
                  f"{modname}.{target}" if modname else None, target]
    domain = env.get_domain("py")
    for path in filter(None, candidates):
        found = _find_object(path)
        if found is None:
            continue
        canonical = _canonical(*found)
        for name in dict.fromkeys((canonical, path)):
            ref = domain.resolve_xref(env, node["refdoc"], app.builder, "obj", name, node, contnode)
            if ref is not None:
                return ref
        return contnode
    node["refspecific"] = True           # a short name in prose: the one documented object it ends
    try:                                 # (several leave a warning that names them)
        return domain.resolve_xref(env, node["refdoc"], app.builder, node["reftype"], target, node, contnode)
    finally:
        node["refspecific"] = False


def setup(app) -> dict:
    logging.getLogger("sphinx.sphinx.directives.other").addFilter(_EmptyGuidesGlob())
    app.connect("autodoc-skip-member", _skip_member)
    app.connect("missing-reference", _resolve_as_python_does)
    return {"parallel_read_safe": True}
