"""Fixtures shared by several test modules.

fresh_generated: the shipped robots generated once per session into a temporary folder, without
the cache (what ``generate(load_models(), out, use_cache=False)`` writes into an empty folder), for
the modules that test freshly generated code rather than the committed generated/. Each module
takes its own copy (fresh_copy), so nothing one module writes there (a build, a __pycache__) is
seen by another; the session's folder itself is only read.

committed_library: the committed generated/<robot>/c built once per session into a shared library
(strict C99, -Wall -Wextra -Werror -pedantic, -O1), double or float: tests/test_codegen.py and
tests/test_regressor.py call the same build.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from derive.codegen.generate import generate
from util import build_library, robots

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]


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


@pytest.fixture(scope="session")
def committed_library(tmp_path_factory):
    """committed_library(robot, extra=()) -> the shared library of every C file of generated/<robot>/c,
    built with STRICT -O1 -fPIC and ``extra`` (say -DDERIVE_FLOAT) once per session."""
    folder, built = tmp_path_factory.mktemp("committed_c"), {}

    def get(robot: str, extra=()) -> Path:
        key = (robot, tuple(extra))
        if key not in built:
            built[key] = build_library(["cc", *STRICT, "-O1", "-fPIC", *extra], sorted((GENERATED / robot / "c").glob("*.c")),
                                       folder / f"lib{robot}{'_'.join(extra)}.so")
        return built[key]

    return get

