"""The bodies of the JSON API's requests and answers, as its OpenAPI schema shows them."""

from __future__ import annotations

import unicodedata
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictBool,
    StrictFloat,
    StrictInt,
    StrictStr,
    field_validator,
)

from pkwbus import __version__
from pkwbus.protocol import pkw

__all__ = [
    "ERRORS",
    "AlarmView",
    "DriveOverview",
    "DriveView",
    "ErrorBody",
    "EventView",
    "EventsBody",
    "Health",
    "LineView",
    "MaintenanceBody",
    "MaintenanceResult",
    "MaintenanceView",
    "MasterView",
    "NotMasterDetail",
    "NotMasterError",
    "ParameterReading",
    "Readiness",
    "ReloadResult",
    "RestoreBody",
    "SlaveView",
    "ValueBody",
    "WritableView",
    "WriteBody",
    "WriteResult",
]


class ParameterReading(BaseModel):
    parameter: str
    index: int
    value: float | int | str  # full precision
    raw: int | None
    unit: str
    timestamp: float
    # How often it is polled, seconds: a value is stale only when it is older than that
    # (None: not polled on a schedule).
    interval: float | None = None
    name: str = ""  # as the configuration, the drive or the catalog names it; else empty
    shown: str = ""  # the value to its resolution, for people (the status page)
    # The unit to show after ``shown``: ``unit``, but empty where ``shown`` names its own (a
    # duration such as "13 h").
    shown_unit: str = ""
    option: str = ""  # an enumeration's text for the value, from the catalog's source
    # Where its type and scaling came from: config, drive (its own description), catalog, none.
    source: str = "catalog"


class AlarmView(BaseModel):
    """An active alarm or warning: the drive's code and the vendor's text for it (empty
    where no named document explains it), since when it is shown."""

    code: str
    text: str
    kind: str = Field(description="alarm or warning")
    parameter: str  # the alarm word or fault number parameter that shows it
    since: float  # wall clock, seconds


class WritableView(BaseModel):
    """A parameter the API may write on the drive: its limits (as described now) and the
    latest value the drive confirmed (None: none yet), for a write form."""

    parameter: str
    index: int
    name: str
    unit: str
    minimum: float | None
    maximum: float | None
    value: float | int | str | None
    text: bool = False  # a text parameter: the new value is a string
    options: dict[int, str] = {}  # an enumeration's numbers and their texts (catalog)


class SlaveView(BaseModel):
    """A PROFIBUS DP slave in the live list: its state, and its latest diagnosis."""

    state: str
    ident: int | None  # from its diagnosis (None: none read yet)
    owner: int | None  # the master that owns it, by its diagnosis (None: none)
    diagnosis: list[str]  # the flags of its latest diagnosis, in words (VIPA IM 353 names)
    diagnosed: float | None  # wall clock of that diagnosis


class MaintenanceView(BaseModel):
    """A drive in maintenance: nothing goes out to it."""

    reason: str
    since: float  # wall clock, seconds


# What a line of text cannot hold: control characters (C0, C1: newline, tab, escape),
# format controls (a right-to-left override) and the line and paragraph separators.
_NOT_IN_A_LINE = frozenset({"Cc", "Cf", "Zl", "Zp"})


class MaintenanceBody(BaseModel):
    model_config = ConfigDict(extra="forbid")

    on: StrictBool = Field(description="true: nothing goes out to the drive until false")
    reason: StrictStr = Field(
        default="", max_length=200, description="shown with it; one line, no control characters"
    )

    @field_validator("reason")
    @classmethod
    def _one_line(cls, reason: str) -> str:
        # A newline (any control character) would start a line of its own in the audit's
        # table and in the log, as if another entry.
        if any(unicodedata.category(c) in _NOT_IN_A_LINE for c in reason):
            raise ValueError("one line of text: no newline, tab or other control character")
        return reason


class RestoreBody(BaseModel):
    model_config = ConfigDict(extra="forbid")

    backup: dict[str, Any] = Field(description="a backup document (GET .../backup)")
    dry_run: StrictBool = Field(default=False, description="plan the writes, write nothing")
    store: pkw.Store = Field(default=pkw.Store.EEPROM, description="ram or eeprom")
    force: StrictBool = Field(default=False, description="restore a backup of another type")


class MaintenanceResult(BaseModel):
    drive: str
    on: bool
    reason: str
    since: float | None  # wall clock, seconds (None: not in maintenance)


class DriveView(BaseModel):
    name: str
    line: str
    protocol: str
    address: int
    dialect: str
    up: bool
    status_word: int | None
    status: dict[str, bool]
    polled: int = 0  # the values it polls (``values``: those read so far)
    values: list[ParameterReading]
    faults: int = 0  # rejections since the service started
    telegram_errors: int = 0  # exchanges without a usable answer since the service started
    alarms: list[AlarmView] = []  # active alarms first, then warnings, oldest first
    writable: list[WritableView] = []  # what the write form offers
    dp: SlaveView | None = None  # a PROFIBUS DP slave: its place in the live list
    maintenance: MaintenanceView | None = None  # in maintenance: nothing goes out to it
    settings: bool = False  # its settings are swept: GET .../settings answers them


class DriveOverview(BaseModel):
    """One drive in a row (``GET /api/v1/drives?view=overview``)."""

    name: str
    line: str
    protocol: str = Field(
        description="its line's bus, as the drive's view names it: fc, uss or profibus"
    )
    address: int
    state: Literal["up", "down", "maintenance"]
    dp_state: str | None = Field(
        default=None, description="a PROFIBUS DP slave: its state in the live list, as its"
        " view's dp.state (null: not a DP slave)",
    )  # fmt: skip
    faults: int = 0  # fault answers since the service started
    telegram_errors: int = 0  # exchanges without a usable answer since the service started
    alarms: list[str] = []  # active alarms in words (code and text), oldest first
    warnings: list[str] = []  # active warnings in words
    updated: float | None = None  # wall clock of its latest polled value (None: none yet)
    age: float | None = None  # seconds since then, at the answer
    settings_changed: int | None = Field(
        default=None, description="its swept settings that differ from their baseline, as"
        " GET .../settings marks them changed (null: its settings are not swept)",
    )  # fmt: skip


class MasterView(BaseModel):
    """The instance that masters a line (hot standby): its name and where to find it."""

    name: str
    url: str | None = Field(default=None, description="its advertised URL (null: none given)")
    here: bool = Field(default=False, description="whether it is the instance answering")


class NotMasterDetail(BaseModel):
    kind: str = Field(description="not_master")
    message: str
    master: str | None = Field(
        description="the instance that masters the drive's line (null: none now)"
    )
    url: str | None = Field(description="that instance's advertised URL (null: none given)")


class NotMasterError(BaseModel):
    """409 for a drive whose line another instance masters (hot standby): ask there."""

    error: NotMasterDetail


class LineView(BaseModel):
    name: str
    master: MasterView | None = Field(
        default=None,
        description="the instance that masters the line in hot standby (null: no hot"
        " standby, or no instance masters it now)",
    )
    open: bool
    drives: int
    drives_up: int
    busy_seconds: float  # since the service started
    utilisation: float | None  # share of the time busy since the last look (None: first look)


class Health(BaseModel):
    status: str
    version: str = __version__


class Readiness(BaseModel):
    ready: bool
    lines: dict[str, bool]
    writes: bool = Field(default=True, description="false while the audit log cannot record")
    reason: str | None = Field(default=None, description="why writes are unavailable")


class WriteBody(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    # Strict: true/false is not 1/0, and "10" stays a string (refused for a number).
    value: StrictInt | StrictFloat | StrictStr = Field(
        description="engineering value, scaled by the catalog; a string for text parameters"
    )
    index: int | None = Field(default=None, ge=0, le=255)
    store: pkw.Store = pkw.Store.RAM
    verify: bool = Field(default=False, description="read the parameter back after writing")
    dry_run: bool = Field(default=False, description="validate and show the telegram only")


class ValueBody(BaseModel):
    parameter: str
    pnu: int
    index: int
    raw: int | None
    value: float | int | str | None = Field(
        description="as the drive answered it; a change through data record 47 is not echoed:"
        " null (verify: true reads it back)"
    )
    unit: str
    access: Literal["pkw", "ds47"] = Field(
        default="pkw", description="the channel that served it: PKW, or data record 47 (DP-V1)"
    )


class WriteResult(ValueBody):
    store: str
    dry_run: bool
    telegram: str = Field(
        description="the request as the drive's carrier sends it (hex): the whole telegram on"
        " FC and USS, the PPO-write on a PROFIBUS PKW slot, the parameter request of data"
        " record 47"
    )
    telegram_note: str | None = Field(
        default=None,
        description="what of the telegram is decided only when it is sent (data record 47:"
        " its request reference); null: nothing",
    )
    audit_id: int | None
    old_value: float | int | str | None = None
    verified: bool | None = None
    audit: Literal["complete", "incomplete"] = Field(
        default="complete", description="incomplete: the audit row could not be fully stored"
    )


class EventView(BaseModel):
    """One entry of a drive's own log, as the drive logged it."""

    line: str
    drive: str
    kind: str = Field(description="fault, alarm or warning")
    code: str = Field(description="the drive's code, as its documents show it (F07801)")
    text: str = Field(description="the vendor's text for the code (empty: no document has one)")
    value: int | None = Field(description="the value the drive logged with it (None: none)")
    time: str = Field(description="ISO 8601, from the drive's own time base (time_source)")
    time_source: Literal["drive_clock", "runtime", "seen"] = Field(
        description="drive_clock: its real-time clock; runtime: its runtime counter, mapped"
        " to the wall clock (exact while it stayed powered since); seen: when pkwbus first"
        " read the entry (the log has no usable time)"
    )
    drive_time: str = Field(description="the entry's time as the drive gave it (empty: none)")
    seen: str = Field(description="ISO 8601: when pkwbus first read the entry")


class EventsBody(BaseModel):
    events: list[EventView]


class ErrorBody(BaseModel):
    error: dict[str, object]


class ReloadResult(BaseModel):
    """A reload that loaded the file: what changed, what takes a restart, lines that could
    not start."""

    loaded: bool
    changes: list[str]
    refused: list[str]
    problems: list[str]
    audit: str | None = None


ERRORS: dict[int | str, dict[str, object]] = {
    code: {"model": ErrorBody} for code in (401, 403, 404, 409, 413, 422, 429, 503, 504)
}
# A drive's read, write or job: also 409 not_master, in hot standby.
ERRORS[409] = {"model": ErrorBody | NotMasterError}
