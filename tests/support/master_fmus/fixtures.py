"""Shared helpers for the master tests: built FMUs and small system factories."""

from __future__ import annotations

import pytest

from master_fmus.build import build_all


@pytest.fixture(scope="session")
def fmus():
    """Paths of the tiny test FMUs, built once (cached across sessions by hash)."""
    return build_all()
