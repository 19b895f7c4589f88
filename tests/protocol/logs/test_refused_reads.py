"""A log whose entries the drive will not give tells nothing, rather than a log with
holes: the SINAMICS fault buffer (r0947 refused), the SINAMICS alarm buffer (r2122
refused) and the Danfoss alarm log (15-30 refused); what each watches between sweeps."""

from __future__ import annotations

from pkwbus.protocol.logs import (
    DANFOSS_ALARM_LOG,
    SINAMICS_ALARM_BUFFER,
    SINAMICS_FAULT_BUFFER,
    Opaque,
    Read,
)
from tests.protocol.logs.test_logs import Drive, sweep


def refusing(pnu: int, index: int) -> Drive:
    """A drive with an empty log that refuses the one read ``pnu[index]``."""

    def drive(read: Read) -> int | None:
        return None if (read.pnu, read.index) == (pnu, index) else 0

    return drive


def test_a_fault_buffer_whose_fault_number_is_refused_tells_nothing() -> None:
    assert sweep(SINAMICS_FAULT_BUFFER, lambda r: 0) is not None  # empty, all answered
    assert sweep(SINAMICS_FAULT_BUFFER, refusing(947, 3)) is None


def test_an_alarm_buffer_whose_alarm_code_is_refused_tells_nothing() -> None:
    assert sweep(SINAMICS_ALARM_BUFFER, lambda r: 0) is not None
    assert sweep(SINAMICS_ALARM_BUFFER, refusing(2122, 5)) is None


def test_a_danfoss_alarm_log_whose_error_code_is_refused_tells_nothing() -> None:
    assert sweep(DANFOSS_ALARM_LOG, lambda r: 0) is not None
    assert sweep(DANFOSS_ALARM_LOG, refusing(1530, 9)) is None


def test_what_each_log_watches_between_sweeps() -> None:
    # SINAMICS: r0944, the fault buffer's change counter; r2121, the alarm buffer's.
    assert SINAMICS_FAULT_BUFFER.watch() == (Read(944),)
    assert SINAMICS_ALARM_BUFFER.watch() == (Read(2121),)
    # Danfoss: no counter; the newest entry's code (15-30[0]) and time (15-32[0]).
    assert DANFOSS_ALARM_LOG.watch() == (Read(1530, 0), Read(1532, 0))


def test_a_time_no_document_explains_shows_as_its_number() -> None:
    assert str(Opaque(123456)) == "123456"
