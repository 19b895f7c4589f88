"""The async tests themselves run on pkwbus's event loop (tests/conftest.py)."""

from __future__ import annotations

import asyncio

from pkwbus.link.eventloop import has_fine_timers


async def test_tests_run_on_the_select_loop() -> None:
    assert has_fine_timers(asyncio.get_running_loop())
