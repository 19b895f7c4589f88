"""Async tests run on the event loop the service and the commands run on.

Hypothesis runs without deadlines and without the too-slow health check: on a
loaded two-core CI machine one example can take far longer than usual, and a
test must not fail for that. With ``CI`` set (``.ci/run`` sets it) the examples
are derandomized: the same ones at every run, so that a landing is judged on
the code and not on a draw; runs without it keep exploring new examples.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Mapping
from typing import Any

import pytest
from hypothesis import HealthCheck, settings

from pkwbus.link import new_event_loop

# The services the tests start reload on SIGHUP unless whoever started them ignores it, as
# nohup does (pkwbus keeps it ignored, on purpose): a test run started under nohup gives
# its services the default again, so that what a reload test sends is heard.
if signal.getsignal(signal.SIGHUP) is signal.SIG_IGN:
    signal.signal(signal.SIGHUP, signal.SIG_DFL)

settings.register_profile("pkwbus", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("pkwbus-ci", settings.get_profile("pkwbus"), derandomize=True)
settings.load_profile("pkwbus-ci" if os.environ.get("CI") else "pkwbus")


def pytest_asyncio_loop_factories(config: pytest.Config, item: pytest.Item) -> Mapping[str, Any]:
    return {"pkwbus": new_event_loop}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The three-minute soak (tests/soak) first: ``make test-long`` runs on two workers,
    and the longest test started last would leave one worker idle for minutes."""
    items.sort(key=lambda item: not item.nodeid.startswith("tests/soak/"))
