"""The plan of a restore: what differs is written in the backup's order; what cannot be
written is skipped with its reason (read-only, no bus access by FC element 21, outside the
target's limits, refused by the target, another drive type unless forced)."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError

from pkwbus.catalog.description import ParameterDescription
from pkwbus.protocol.pkw.descriptions import Characteristics
from pkwbus.protocol.values import ValueType
from pkwbus.service.history.backup import Backup, Present, drive_type, plan_restore

FC_302 = "fc:FC-302P7K5T5|05.11"
FC_102 = "fc:FC-102P11KT4|05.11"
RAMP = ParameterDescription("Ramp 1 Ramp Up Time", ValueType.U32, minimum=0.01, maximum=3600.0)


def backup(*settings: dict[str, Any], identity: str = FC_302) -> Backup:
    return Backup.model_validate({"drive": "a", "identity": identity, "settings": settings})


def present(value: Any, **more: Any) -> Present:
    return Present(value, more.pop("fmt", RAMP), **more)


def test_only_what_differs_is_planned_in_the_backups_order() -> None:
    b = backup(
        {"parameter": "3-42", "value": 8.0},
        {"parameter": "3-41", "value": 5.0},
        {"parameter": "4-14", "value": 50.0},
    )
    now = {("3-42", 0): present(10.0), ("3-41", 0): present(5.0), ("4-14", 0): present(45.0)}
    plan, skipped = plan_restore(b, now, target_identity=FC_302)
    assert [(p.parameter, p.old, p.new) for p in plan] == [
        ("3-42", 10.0, 8.0),
        ("4-14", 45.0, 50.0),
    ]
    assert skipped == []


@pytest.mark.parametrize(
    ("now", "why"),
    [
        (present(1.0, read_only=True), "read-only"),
        (present(1.0, characteristics=Characteristics(1 << 11)), "read-only"),
        (present(1.0, characteristics=Characteristics(1 << 9)), "no bus access"),
        (present(None, refused="The parameter number used does not exit"), "refuses"),
        (present(None), "did not answer"),
        (present(1.0, fmt=ParameterDescription("x", ValueType.U32, maximum=100.0)), "limits"),
    ],
)
def test_what_cannot_be_written_is_skipped_with_its_reason(now: Present, why: str) -> None:
    plan, skipped = plan_restore(
        backup({"parameter": "3-41", "value": 120.0}), {("3-41", 0): now}, target_identity=FC_302
    )
    assert plan == []
    (found,) = skipped
    assert found.parameter == "3-41" and why in found.why


def test_a_characteristic_that_allows_the_bus_does_not_skip() -> None:
    allowed = Characteristics(1 << 8 | 1 << 13)  # LCP read/write; not while running
    plan, _ = plan_restore(
        backup({"parameter": "1-20", "value": 11.0}),
        {("1-20", 0): present(15.0, characteristics=allowed)},
        target_identity=FC_302,
    )
    assert [p.new for p in plan] == [11.0], "the drive says why, if it runs"


def test_a_backup_of_another_drive_type_is_skipped_whole_unless_forced() -> None:
    b = backup({"parameter": "3-41", "value": 5.0})
    now = {("3-41", 0): present(10.0)}
    plan, skipped = plan_restore(b, now, target_identity=FC_102)
    assert plan == [] and "another drive type" in skipped[0].why
    plan, skipped = plan_restore(b, now, target_identity=FC_102, force=True)
    assert [p.new for p in plan] == [5.0] and skipped == []
    # Another software version of the same model is the same type.
    plan, _ = plan_restore(b, now, target_identity="fc:FC-302P7K5T5|06.02")
    assert [p.new for p in plan] == [5.0]


def test_the_type_of_a_drive_is_its_model_without_its_software() -> None:
    assert drive_type(FC_302) == "fc:FC-302P7K5T5"
    assert drive_type("uss:42|1|4710") == "uss:42|1"  # r0964 company and device type
    assert drive_type(None) is None


@pytest.mark.parametrize(
    "document",
    [
        {"settings": []},  # no drive
        {"drive": "a", "settings": [{"parameter": "3-41", "index": 300}]},
        {"drive": "a", "pkwbus_backup": 2},
        {"drive": "a", "settings": [{"parameter": "3-41", "value": [1]}]},
        {"drive": "a", "unknown": 1},
    ],
)
def test_a_document_that_is_not_a_backup_is_refused(document: dict[str, Any]) -> None:
    with pytest.raises(ValidationError):
        Backup.model_validate(document)


@pytest.mark.parametrize(
    ("document", "dialect", "catalog", "other"),
    [
        # No identity on either side (describe: off, a PPO's four words): the catalog tells.
        ({"catalog": "siemens-g120", "dialect": "uss"}, "fc", "danfoss-fc", "another catalog"),
        # Neither names a catalog: the dialect tells ("1120" is 11-20 on an FC drive).
        ({"dialect": "uss"}, "fc", None, "another dialect"),
        # The same catalog over another bus (FC protocol, then PROFIBUS): the same kind.
        ({"catalog": "danfoss-fc", "dialect": "fc"}, "danfoss-pcv", "danfoss-fc", None),
    ],
)
def test_a_backup_of_another_kind_of_drive_is_told_without_identities(
    document: dict[str, Any], dialect: str, catalog: str | None, other: str | None
) -> None:
    b = Backup.model_validate(
        {"drive": "a", "settings": [{"parameter": "1120", "value": 5.0}], **document}
    )
    now = {("1120", 0): present(10.0)}
    plan, skipped = plan_restore(
        b, now, target_identity=None, target_dialect=dialect, target_catalog=catalog
    )
    if other is None:
        assert [p.new for p in plan] == [5.0] and skipped == []
    else:
        assert plan == [] and other in skipped[0].why
        forced, _ = plan_restore(b, now, target_identity=None, target_dialect=dialect,
                                 target_catalog=catalog, force=True)  # fmt: skip
        assert [p.new for p in forced] == [5.0]


@pytest.mark.parametrize("number", [float("nan"), float("inf"), float("-inf")])
def test_a_value_that_is_not_a_finite_number_is_no_backup(number: float) -> None:
    with pytest.raises(ValidationError):
        Backup.model_validate({"drive": "a", "settings": [{"parameter": "3-41", "value": number}]})
