"""Fixtures shared by several test modules.

fresh_generated: the shipped robots generated once per session into a temporary folder, without
the cache (what ``generate(load_models(), out, use_cache=False)`` writes into an empty folder), for
the modules that test freshly generated code rather than the committed generated/. Each module
takes its own copy (fresh_copy), so nothing one module writes there (a build, a __pycache__) is
seen by another; the session's folder itself is only read.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from derive.codegen.generate import generate
from util import robots


@pytest.fixture(scope="session")
def fresh_generated(tmp_path_factory) -> Path:
    """generated/ as derive writes it now: every shipped robot, derived without the cache. Read only."""
    out = tmp_path_factory.mktemp("fresh") / "generated"
    generate(robots(), out, use_cache=False, log=lambda s: None)
    return out


@pytest.fixture(scope="session")
def fresh_copy(fresh_generated, tmp_path_factory):
    """fresh_copy(name) -> a new folder <tmp>/<name>/generated holding a copy of fresh_generated."""

    def copy(name: str) -> Path:
        out = tmp_path_factory.mktemp(name) / "generated"
        shutil.copytree(fresh_generated, out)
        return out

    return copy
