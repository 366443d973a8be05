"""Fuzz-test budget: a few dozen examples per property in the default run, many under -m slow.

A fuzz test takes the ``fuzz`` fixture and decorates its inner ``@given`` function with it::

    def test_loader(fuzz):
        @fuzz
        @given(st.binary())
        def check(data): ...
        check()

Each test then runs twice: ``[bounded]`` in the default run, ``[thorough]`` (marked slow).
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, settings

_BUDGETS = {"bounded": 30, "thorough": 600}


@pytest.fixture(params=[pytest.param("bounded"),
                        pytest.param("thorough", marks=pytest.mark.slow)])
def fuzz(request: pytest.FixtureRequest) -> settings:
    # No deadline: a 2-core CI machine shared with other jobs makes per-example times noisy.
    # No example database: runs stay independent of what an earlier run found.
    return settings(max_examples=_BUDGETS[request.param], deadline=None, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])
