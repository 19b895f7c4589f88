"""The short form of ``make soak``: three minutes on three lines (FC, USS, PROFIBUS DP),
with troubles ten times as often, a reload a minute, a sample every 6 s. ``make
test-long`` runs it."""

from __future__ import annotations

from pathlib import Path

import pytest

from .run import Settings, soak


@pytest.mark.long
async def test_three_minutes_on_three_lines_with_faults_lost_ports_and_restarts(
    tmp_path: Path,
) -> None:
    settings = Settings(
        minutes=3, lines=3, sample_every=6, drops_per_hour=60, restarts_per_hour=100,
        deaths_per_hour=40, reloads_per_hour=60, folder=tmp_path, say=False,
    )  # fmt: skip
    result = await soak(settings)
    report = result.report()
    print(report)
    assert result.verdict() == [], report
    events = result.events["events"]
    assert isinstance(events, dict)
    # The troubles happened (the draws are seeded), and the soak looked at the service.
    for what in ("port_lost", "restart", "drive_dead"):
        assert sum(n for event, n in events.items() if event.endswith(what)) > 0, events
    assert len(result.samples) >= 25
    assert result.counts["writes"] >= 45 and result.counts["values checked"] > 1000
    # Reloads applied in place while all that went on, each loaded.
    assert result.counts["reloads sent"] >= 2
    assert result.counts["reloads loaded"] == result.counts["reloads sent"]
