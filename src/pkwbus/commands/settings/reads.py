"""What `pkwbus backup` and `pkwbus restore` read of one drive, on any bus
(:mod:`pkwbus.commands.drive_access`): its identity, its Danfoss active set-up, and
what it says of its settings (their description elements and values).

The settings are those of a catalog (each element of an array), named as the drive
names them (``3-41`` on an FC drive, ``p1120`` on a Siemens one). A value is decoded
as `pkwbus read` decodes it, with the catalog's entry, over which the drive's own
description counts where it gives one (:func:`pkwbus.catalog.precedence.resolve`),
as the service does.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for a catalog
that does not load, a request that cannot be sent, or a drive that does not answer.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from pkwbus import link
from pkwbus.catalog import CatalogError, load_catalog
from pkwbus.catalog.description import ParameterDescription
from pkwbus.catalog.precedence import Layers, resolve
from pkwbus.commands.answers import drive_name
from pkwbus.commands.common import CommandError, Exit, duration_option
from pkwbus.commands.drive_access import DriveAccess, checked
from pkwbus.commands.failures import command_failure
from pkwbus.master.planning.identity import identity_of, identity_requests
from pkwbus.master.planning.outcomes import Answered, Outcome, Rejected
from pkwbus.notation import durations
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import (
    CHARACTERISTICS,
    NAME,
    Characteristics,
    DescriptionForm,
    DriveDescription,
    elements_to_read,
    form_of,
    read_elements,
)
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.values import ParameterRef

__all__ = [
    "SETUP_PNU",
    "Described",
    "Setting",
    "add_deadline_option",
    "catalog_settings",
    "describe_settings",
    "formats",
    "identify",
    "run_all",
]

# Danfoss 0-10 "Active Set-up" ("[9] Multi set-ups ... in parameter 0-10 Active Set-up":
# Danfoss VLT CANopen MCA 105 manual, "Bit 13/14, Selection of set-up").
SETUP_PNU = 10


@dataclass(frozen=True, slots=True)
class Setting:
    """One setting of a catalog under the drive's name for it (``index`` None where the
    catalog has no array), and the catalog's entry."""

    ref: ParameterRef
    known: ParameterDescription


@dataclass(frozen=True, slots=True)
class Described:
    """What the drive says of one parameter: its description elements (empty where it
    gives none) and FC element 21 (None where not read or refused)."""

    drive: DriveDescription
    characteristics: Characteristics | None = None


def add_deadline_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--deadline",
        type=duration_option(durations.JOB_DEADLINE),
        default=2.0,
        help=f"for each request, retries included (default 2s; {durations.JOB_DEADLINE})",
    )


def catalog_settings(catalog: str, dialect: Dialect) -> list[Setting]:
    """The settings of ``catalog`` (its entries whose ``is_setting`` holds), in its order,
    each element of an array; none for 'none'. A catalog that does not load is a bad
    option (exit 2)."""
    if catalog == "none":
        return []
    try:
        specs = load_catalog(catalog).parameters.values()
    except CatalogError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    found: list[Setting] = []
    for spec in specs:
        if not spec.is_setting:
            continue
        known = ParameterDescription.from_spec(spec)
        base = drive_name(ParameterRef(spec.pnu, None, str(spec.pnu)), dialect, known)
        indexes: Iterable[int | None] = range(spec.array) if spec.array else (None,)
        found.extend(Setting(ParameterRef(spec.pnu, i, base.name), known) for i in indexes)
    return found


def run_all(access: DriveAccess, requests: Sequence[pkw.PkwRequest]) -> list[Outcome]:
    """``requests``, one after the other in one opening of the port; the first that got
    neither an answer nor a refusal ends the command (exit 3 for no answer)."""
    if not requests:
        return []
    outcomes = link.run(access.run(checked(access, requests), None))
    for outcome in outcomes:
        failure = None if isinstance(outcome, Answered | Rejected) else command_failure(outcome)
        if failure is not None:
            raise CommandError(failure.message, failure.code, kind=failure.kind)
    return outcomes


def identify(access: DriveAccess, *, setup: bool) -> tuple[str | None, int | None]:
    """The drive's identity (None where it tells none) and, with ``setup`` on a drive
    that describes itself in the Danfoss FC form, its active set-up (0-10, raw; None
    where it refuses it). A drive that does not answer ends the command (exit 3)."""
    d = access.dialect
    requests = list(identity_requests(d, texts=access.texts))
    if setup and form_of(d) is DescriptionForm.DANFOSS_FC:
        requests.append(pkw.read(d, SETUP_PNU))
    else:
        setup = False
    outcomes = run_all(access, requests)
    active: int | None = None
    if setup:
        last = outcomes.pop()
        if isinstance(last, Answered) and isinstance(last.response, pkw.ValueResponse):
            active = last.response.raw
    return identity_of(d, outcomes), active


def describe_settings(
    access: DriveAccess, pnus: Iterable[int], *, limits: bool
) -> dict[int, Described]:
    """What the drive says of each of ``pnus``: type, size, scaling, name, with
    ``limits`` the limits and (FC form) element 21. A dialect without the description
    request (AK 4) says nothing. Read in one opening of the port; no answer: exit 3."""
    d = access.dialect
    form = form_of(d)
    wanted = list(dict.fromkeys(pnus))
    if form is None or not wanted:
        return {pnu: Described(DriveDescription()) for pnu in wanted}
    elements = [e for e in elements_to_read(limits=limits) if e != NAME or access.texts]
    if limits and form is DescriptionForm.DANFOSS_FC:
        elements.append(CHARACTERISTICS)
    requests = [pkw.read_description(d, pnu, e) for pnu in wanted for e in elements]
    outcomes = iter(run_all(access, requests))
    found: dict[int, Described] = {}
    for pnu in wanted:
        said: dict[int, pkw.DescriptionResponse | None] = {}
        for element in elements:
            outcome = next(outcomes)
            answer = outcome.response if isinstance(outcome, Answered) else None
            said[element] = answer if isinstance(answer, pkw.DescriptionResponse) else None
        characteristic = said.pop(CHARACTERISTICS, None)
        found[pnu] = Described(
            read_elements(form, said),
            None if characteristic is None else Characteristics.of(characteristic),
        )
    return found


def formats(known: ParameterDescription, said: Described | None) -> ParameterDescription:
    """The description a value is decoded and encoded with: what the drive says of it
    over the catalog's entry ``known``."""
    drive = None if said is None else said.drive
    return resolve(Layers(known, catalog=known), drive).description
