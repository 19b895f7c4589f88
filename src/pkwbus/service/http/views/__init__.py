"""What the JSON API and the status page show of the lines and the drives: their views,
made from the runtime and its snapshot (the alarms in words, the writable parameters,
the trends of the values)."""

from __future__ import annotations

import datetime

from pkwbus.catalog.description import ParameterKey
from pkwbus.protocol.values import ParameterRef
from pkwbus.service.history.store import DriveEvent
from pkwbus.service.history.times import iso_time
from pkwbus.service.http.models import (
    AlarmView,
    EventView,
    LineView,
    MaintenanceView,
    MasterView,
    SlaveView,
    WritableView,
)
from pkwbus.service.runtime import DriveEntry, Runtime
from pkwbus.service.writes.checks import ApiError

__all__ = [
    "alarm_views",
    "event_views",
    "known_line",
    "line_views",
    "maintenance_view",
    "parse_since",
    "settings_changed",
    "settings_swept",
    "slave_view",
    "trend_views",
    "writable_refs",
    "writable_views",
]


def known_line(runtime: Runtime, name: str) -> bool:
    """Whether ``name`` is a line of this load: one that runs, or one whose drives are here
    though it could not start."""
    return name in runtime.runners or any(e.line == name for e in runtime.drives.values())


def line_views(
    runtime: Runtime, looks: dict[str, tuple[float, float]], now: float
) -> list[LineView]:
    """Each line's port, drives and how busy it was since ``looks`` last saw it."""
    snap = runtime.snapshot
    views = []
    masters = runtime.masters
    by_line: dict[str, list[str]] = {name: [] for name in runtime.runners}
    for d, e in runtime.drives.items():
        by_line.setdefault(e.line, []).append(d)
    # Every line with a runner or a drive (a line a reload could not start has only its
    # drives: it is shown down); in hot standby every configured line, those mastered
    # elsewhere too.
    names = list(by_line) if masters is None else list(masters.lines())
    for name in names:
        mine = by_line.get(name, [])
        up = sum(1 for d in mine if (state := snap.drives.get(d)) is None or state.up)
        if masters is not None and name not in runtime.runners:  # nothing of it runs here
            mine, up = list(masters.lines()[name]), 0
        totals = snap.totals.get(name)
        busy = totals.busy if totals is not None else 0.0
        utilisation = None
        seen = looks.get(name)
        if seen is not None and now > seen[0]:
            utilisation = min(1.0, max(0.0, (busy - seen[1]) / (now - seen[0])))
        looks[name] = (now, busy)
        master = masters.master_of(name) if masters is not None else None
        views.append(
            LineView(
                name=name,
                master=MasterView(name=master.name, url=master.url, here=masters.here(name))
                if master is not None and masters is not None
                else None,
                open=bool(snap.lines.get(name)),
                drives=len(mine),
                drives_up=up,
                busy_seconds=busy,
                utilisation=utilisation,
            )
        )
    return views


def alarm_views(runtime: Runtime, name: str) -> list[AlarmView]:
    """The drive's active alarms and warnings, in words."""
    active = runtime.snapshot.alarms.get(name, ())
    return [
        AlarmView(code=a.alarm.code, text=a.alarm.text, kind=a.alarm.kind,
                  parameter=a.alarm.parameter, since=a.since)
        for a in active
    ]  # fmt: skip


def writable_views(runtime: Runtime, name: str) -> list[WritableView]:
    """The drive's writable parameters, their limits as described now and the latest value
    the drive confirmed."""
    views = []
    for pnu, index, ref in writable_refs(runtime.drives[name]):
        fmt = runtime.format_of(name, ref)
        latest = runtime.snapshot.latest.get((name, pnu, index or 0))
        views.append(
            WritableView(
                parameter=ref.name, index=index or 0, name=fmt.name, unit=fmt.unit,
                minimum=fmt.minimum, maximum=fmt.maximum,
                value=latest.value if latest is not None else None, text=fmt.is_text,
                options=dict(fmt.options) if fmt.enumerates else {},
            )
        )  # fmt: skip
    return views


def writable_refs(entry: DriveEntry) -> tuple[tuple[int, int | None, ParameterRef], ...]:
    """The drive's writable parameters as (PNU, index, its one name), in the order of their
    keys' text; worked out once per entry (an entry never changes: a reload makes a new
    one)."""
    kept = _writable.get(entry.name)
    if kept is not None and kept[0] is entry:
        return kept[1]
    found = tuple(
        (pnu, index, entry.canonical(ParameterRef(pnu, index, "")))
        for (pnu, index), known in sorted(entry.parameters.configured.items(), key=_key_text)
        if known.writable and (index is None or index >= 0)
    )
    if len(_writable) > _WRITABLE_KEPT:
        _writable.clear()
    _writable[entry.name] = (entry, found)
    return found


def _key_text(item: tuple[ParameterKey, object]) -> str:
    """The sort key of a configured parameter: its key's text (the order ``str`` of the
    whole item gave, without writing out the description each time)."""
    return str(item[0])


# Each drive's writable parameters, by name: (the entry they are of, the parameters).
_writable: dict[str, tuple[DriveEntry, tuple[tuple[int, int | None, ParameterRef], ...]]] = {}
_WRITABLE_KEPT = 100_000  # drives: more only after many reloads that renamed drives


def slave_view(runtime: Runtime, name: str) -> SlaveView | None:
    """The drive's place in its DP line's live list (None: no DP slave)."""
    live = runtime.snapshot.slaves.get(name)
    if live is None:
        return None
    flags = sorted(flag.replace("_", " ") for flag in live.flags)
    return SlaveView(
        state=live.state.value, ident=live.ident, owner=live.owner, diagnosis=flags,
        diagnosed=live.diagnosed,
    )  # fmt: skip


def maintenance_view(runtime: Runtime, name: str) -> MaintenanceView | None:
    held = runtime.snapshot.maintenance.get(name)
    return MaintenanceView(reason=held.reason, since=held.since) if held is not None else None


def settings_swept(runtime: Runtime, name: str) -> bool:
    """Whether the drive's settings are swept (``GET .../settings`` has them)."""
    settings = runtime.settings
    return settings is not None and name in settings.swept


def settings_changed(runtime: Runtime, name: str) -> int | None:
    """How many of the drive's swept settings differ from their baseline: those its
    settings view (``GET .../settings``) marks ``changed``, as the read model has it from
    the sweep (:attr:`pkwbus.master.snapshot.Snapshot.settings`; None: its settings are
    not swept, or not read yet)."""
    if not settings_swept(runtime, name):
        return None
    shown = runtime.snapshot.settings.get(name)
    return shown.changed if shown is not None else None


def trend_views(runtime: Runtime, name: str, now: float) -> dict[str, list[float | None]]:
    """The last 15 minutes of each polled numeric value of the drive, oldest first (one
    point a 15 s, None where none landed), by its parameter as the API names it."""
    trends = runtime.trends
    if trends is None:
        return {}
    out: dict[str, list[float | None]] = {}
    readings = runtime.snapshot.readings
    for poll in runtime.drives[name].polls:
        key = (name, poll.parameter, poll.index)
        if key in readings and (points := trends.points(key, now)):
            out[f"{poll.parameter}[{poll.index}]" if poll.index else poll.parameter] = points
    return out


def parse_since(text: str | None) -> float | None:
    """``since`` of a request: ISO 8601 (UTC where it names no offset); ApiError 422."""
    if text is None:
        return None
    try:
        moment = datetime.datetime.fromisoformat(text.strip())
    except ValueError:
        raise ApiError(
            422, "invalid_request", f"since: {text[:40]!r} is not an ISO 8601 time"
            " such as 2026-11-27T08:00:00Z",
        ) from None  # fmt: skip
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=datetime.UTC)
    return moment.timestamp()


def event_views(events: list[DriveEvent]) -> list[EventView]:
    """The drives' log entries as the API shows them; ``time`` is the drive's where it
    gave a usable one, else when pkwbus first read the entry."""
    return [_event_view(e) for e in events]


def _event_view(e: DriveEvent) -> EventView:
    return EventView(
        line=e.line, drive=e.drive, kind=e.kind, code=e.code, text=e.text, value=e.value,
        time=iso_time(e.when), time_source=e.time_source,  # type: ignore[arg-type]
        drive_time=e.drive_time, seen=iso_time(e.seen),
    )  # fmt: skip
