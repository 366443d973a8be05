"""Fixtures for report and export tests (the scenes are built in report_fixtures.py)."""

from __future__ import annotations

import pytest
from report_fixtures import make_room

from monoplane.datamodel import Reconstruction


@pytest.fixture
def room() -> Reconstruction:
    """The room at 160x120 pixels."""
    return make_room()
