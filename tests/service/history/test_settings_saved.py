"""A settings save whose caller is cancelled (the service stopping) still finishes; when
it fails then (the database closed meanwhile) the failure is logged, not left to the event
loop as a task exception nobody retrieved (a traceback in the service's log)."""

from __future__ import annotations

import asyncio
import gc
import logging
import threading
from pathlib import Path
from typing import Any

import pytest

from pkwbus.service.history.settings_store import SettingsStore


class Held(SettingsStore):
    """A store whose save waits until let go: the caller can be cancelled meanwhile."""

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        self.started = threading.Event()
        self.go = threading.Event()

    def save(self, rows: Any, events: Any = ()) -> Any:
        self.started.set()
        self.go.wait(10)
        return super().save(rows, events)


async def test_a_cancelled_saves_failure_is_logged_not_left_unretrieved(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    unretrieved: list[dict[str, Any]] = []
    loop = asyncio.get_running_loop()
    loop.set_exception_handler(lambda _, context: unretrieved.append(context))
    store = Held(tmp_path / "history.sqlite")
    caplog.set_level(logging.WARNING, "pkwbus.service.settings")
    caller = asyncio.create_task(store.saved([]))
    await asyncio.to_thread(store.started.wait, 10)
    caller.cancel()
    with pytest.raises(asyncio.CancelledError):
        await caller
    store.close()  # the service's stop closes the database
    store.go.set()
    for _ in range(500):
        if "settings not stored while the service stopped" in caplog.text:
            break
        await asyncio.sleep(0.01)
    gc.collect()
    await asyncio.sleep(0)
    assert "settings not stored while the service stopped" in caplog.text
    assert "is closed" in caplog.text
    assert unretrieved == []
