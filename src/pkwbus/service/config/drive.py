"""What every drive (follower) on a line has, whatever its bus: its name, address, dialect,
catalog and parameters. Each bus's drive adds its own settings (:mod:`.serial`,
:mod:`.profibus`)."""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Iterator, Mapping, Sequence
from typing import ClassVar, Self

from pydantic import (
    Field,
    StrictBool,
    StrictInt,
    ValidationInfo,
    field_validator,
    model_validator,
)

from pkwbus.catalog import ParameterSpec
from pkwbus.protocol.buses import Bus, default_dialect
from pkwbus.protocol.pkw.dialects import Dialect, IndLayout, dialect
from pkwbus.protocol.serial.telegram import BlockShape
from pkwbus.protocol.values import (
    ParameterRef,
    canonical,
    siemens_name,
)
from pkwbus.service.config.base import Model, Place, fail
from pkwbus.service.config.catalogs import Catalogs, builtin_catalogs, catalogs_of
from pkwbus.service.config.fields import (
    Alarms,
    Counters,
    Describe,
    Events,
    EventsEvery,
    Name,
    Notation,
    SettingsField,
)
from pkwbus.service.config.parameters import ParameterOverrides, Poll, ref_key

__all__ = ["DriveBase", "duplicates"]


class DriveBase(Model):
    """One drive (follower) on a line: what drives of every bus have."""

    # The bus of the drive's line: each bus's drive is its own class.
    protocol: ClassVar[Bus]
    # Keys the drive does not take, each with what a user who gives one is told (its line
    # takes them out and tells them with its own problems: :class:`~.line.LineBase`).
    refused_keys: ClassVar[Mapping[str, str]] = {
        "protocol": "is the line's setting: give the protocol once, on the line"
    }

    name: Name
    address: StrictInt
    dialect: str | None = Field(default=None, strict=True)
    catalog: str | None = Field(default=None, strict=True)
    # The drive's own description elements (AK 4) over the catalog; None: the line's setting.
    describe: Describe | None = None
    # Poll the alarm words its catalog explains even where ``poll`` does not: auto or off
    # (None: the line's setting).
    alarms: Alarms | None = None
    # Poll the counters its catalog marks (operating hours, energy, power-ups) even where
    # ``poll`` does not: auto or off (None: the line's setting).
    counters: Counters | None = None
    # Its own fault and alarm logs, and how often they are watched (None: the line's).
    events: Events | None = None
    events_every: EventsEvery | None = None
    # The sweep of its settings (None: the line's).
    settings: SettingsField | None = None
    # In maintenance from the start: nothing goes out to it until the API takes it out.
    maintenance: StrictBool = False
    poll: list[Poll] = Field(default_factory=list)
    writable: list[Notation] = Field(default_factory=list)
    parameters: dict[Notation, ParameterOverrides] = Field(default_factory=dict)

    @field_validator("dialect")
    @classmethod
    def _known_dialect(cls, value: str | None) -> str | None:
        if value is not None:
            dialect(value)
        return value

    @field_validator("catalog")
    @classmethod
    def _known_catalog(cls, value: str | None, info: ValidationInfo) -> str | None:
        if value is None:
            return None
        catalogs = catalogs_of(info)
        try:
            catalogs.load(value)
        except LookupError:
            known = ", ".join(catalogs.available()) or "none installed"
            raise ValueError(f"unknown catalog {value!r} (available: {known})") from None
        return value

    @model_validator(mode="after")
    def _unique_parameters(self) -> Self:
        problems = duplicates("poll", [p.ref for p in self.poll], "parameter", "polled")
        problems += duplicates("writable", self.writable, "", "listed")
        problems += duplicates("parameters", list(self.parameters), "", "given")
        overridden = {ref_key(ref) for ref in self.parameters}
        for i, entry in enumerate(self.poll):
            if entry.given() and ref_key(entry.ref) in overridden:
                problems.append(
                    (f"poll[{i}]", f"{entry.ref} has overrides both here and under parameters")
                )
        if problems:
            raise fail(problems)
        return self

    @model_validator(mode="after")
    def _fits_catalog(self, info: ValidationInfo) -> Self:
        """Overrides must agree with the catalog entry they change; indexes fit arrays."""
        catalogs = catalogs_of(info)
        problems: list[Place] = []
        for place, ref in self.refs():
            try:
                spec = self.spec(ref, catalogs)
            except ValueError as exc:
                problems.append((place, f"{ref}: {str(exc).removeprefix('override: ')}"))
                continue
            if spec and spec.array and ref.index is not None and ref.index >= spec.array:
                problems.append((place, f"{ref}: the catalog gives it {spec.array} elements"))
        for i, ref in enumerate(self.writable):
            if ref.prefix == "r":
                problems.append((f"writable[{i}]", f"{ref} is read-only (r): settable ones are p"))
            elif self._catalog_prefix(ref.pnu, catalogs) == "r":
                name = siemens_name("r", ref.pnu)
                problems.append((f"writable[{i}]", f"{ref} is {name}, read-only (r)"))
        if problems:
            raise fail(problems)
        return self

    def spec(self, ref: ParameterRef, catalogs: Catalogs | None = None) -> ParameterSpec | None:
        """What is known of ``ref`` on this drive: its catalog entry with the config's overrides.

        From the overrides alone when the catalog lacks it; None when neither
        says anything (the value is read and exported raw). ValueError when
        the overrides do not fit the catalog entry (min above its max, say).
        """
        changes = self.overrides_for(ref).changes()
        base = None
        if self.catalog is not None:
            base = (catalogs or builtin_catalogs()).load(self.catalog).get(ref.pnu)
        if base is None:
            if not changes:
                return None
            base = ParameterSpec(pnu=ref.pnu, name=ref.name)
        return base.overridden(changes) if changes else base

    @property
    def pkw_dialect(self) -> Dialect:
        """The dialect, given or the protocol's default."""
        return dialect(self.dialect or default_dialect(self.protocol))

    @property
    @abstractmethod
    def layout(self) -> IndLayout:
        """The IND layout of its parameter requests."""

    @property
    @abstractmethod
    def shape(self) -> BlockShape:
        """The data block of a parameter telegram: its PKW and PZD words."""

    @property
    @abstractmethod
    def sim_shape(self) -> tuple[object, ...]:
        """What one simulator answers all drives of a ``sim://`` line with: the same for
        each of them."""

    def refs(self) -> Iterator[tuple[str, ParameterRef]]:
        """Every parameter the drive's config names, with its place."""
        for i, entry in enumerate(self.poll):
            yield f"poll[{i}].parameter", entry.ref
        for i, ref in enumerate(self.writable):
            yield f"writable[{i}]", ref
        for ref in self.parameters:
            yield f"parameters[{ref}]", ref
        listed = None if isinstance(self.settings, str | None) else self.settings.parameters
        if isinstance(listed, list):
            for i, ref in enumerate(listed):
                yield f"settings.parameters[{i}]", ref

    def overrides_for(self, ref: ParameterRef) -> ParameterOverrides:
        """The config's overrides for ``ref``: its poll entry's, else ``parameters``'."""
        for entry in self.poll:
            if ref_key(entry.ref) == ref_key(ref) and entry.given():
                return entry.overrides()
        for key in (ref_key(ref), (ref.pnu, None)):
            for given, overrides in self.parameters.items():
                if ref_key(given) == key:
                    return overrides
        return ParameterOverrides()

    def canonical(self, ref: ParameterRef, catalogs: Catalogs | None = None) -> ParameterRef:
        """``ref`` under this drive's one name for it, as labels, the API and the audit
        show it: ``3-41`` on a Danfoss drive (written ``341`` or ``0341``; r/p is a
        LocalProtocolError), else ``r0021``/``p1082`` with the prefix of the catalog,
        else of this configuration, else the plain number."""
        numbers = self.pkw_dialect.danfoss_numbers
        return canonical(ref, danfoss=numbers, prefix=self.prefix_of(ref.pnu, catalogs))

    def prefix_of(self, pnu: int, catalogs: Catalogs | None = None) -> str:
        """The r/p of ``pnu``: the catalog's, else the first this configuration writes."""
        given = (ref.prefix for _, ref in self.refs() if ref.pnu == pnu and ref.prefix)
        return self._catalog_prefix(pnu, catalogs) or next(given, "")

    def _catalog_prefix(self, pnu: int, catalogs: Catalogs | None) -> str:
        if self.catalog is None:
            return ""
        spec = (catalogs or builtin_catalogs()).load(self.catalog).get(pnu)
        return spec.prefix if spec is not None else ""

    def may_write(self, ref: ParameterRef) -> bool:
        """Whether ``writable`` lists ``ref`` (an entry without index allows every index)."""
        return any(
            w.pnu == ref.pnu and (w.index is None or w.index == ref.index) for w in self.writable
        )


def duplicates(field: str, refs: Sequence[ParameterRef], leaf: str, verb: str) -> list[Place]:
    seen: dict[tuple[int, int | None], int] = {}
    problems: list[Place] = []
    for i, ref in enumerate(refs):
        place = f"{field}[{i}]" + (f".{leaf}" if leaf else "")
        if field == "parameters":
            place = f"parameters[{ref}]"
        first = seen.setdefault(ref_key(ref), i)
        if first != i:
            problems.append((place, f"{ref} is {verb} twice (also {field}[{first}])"))
    return problems
