"""Async tests run on the event loop the service and the commands run on."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pytest

from pkwbus.link import new_event_loop


def pytest_asyncio_loop_factories(config: pytest.Config, item: pytest.Item) -> Mapping[str, Any]:
    return {"pkwbus": new_event_loop}
