"""Where derive's own files are: its templates and the shipped example models.

In a source checkout they are the project's ``templates/`` and ``models.yaml`` beside
the package; a built wheel carries the same files under ``derive/_data/`` (see
pyproject.toml), so an installed derive finds them from any folder.
"""

from __future__ import annotations

from pathlib import Path

PACKAGE = Path(__file__).resolve().parent


def data_path(name: str) -> Path:
    """A file or folder shipped with derive: the installed copy, else the checkout's."""
    installed = PACKAGE / "_data" / name
    return installed if installed.exists() else PACKAGE.parent / name


TEMPLATES = data_path("templates")
"""jinja2 templates and verbatim support files, one folder per language (``c/``, ``python/``, ...)."""

EXAMPLES = data_path("examples")
"""The example models, mechanisms and programs (``examples/`` of the checkout), shipped in the wheel."""

EXAMPLE_MODELS = data_path("models.yaml")
"""The shipped robots (pendulum, planar_2r, rrprr, cartpole, ur5, panda): ``derive init`` copies them."""

CHECKOUT = PACKAGE.parent
"""The folder holding the package: the project's root in a source checkout."""
