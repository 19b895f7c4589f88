"""The view of the keys when etcd is no longer the store it was read from (its data lost,
restored from an older snapshot, another cluster): forgotten and read anew."""

from __future__ import annotations

from pkwbus.service.standby.etcd import Event, KeyValue
from pkwbus.service.standby.view import Master, View, master_value

CLUSTER = "15118495548433857066"


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def line(name: str, holder: str, lease: int, revision: int) -> KeyValue:
    return KeyValue(f"/t/lines/{name}", master_value(holder, None), lease, revision, revision)


def instance(name: str, lease: int, revision: int) -> KeyValue:
    return KeyValue(f"/t/instances/{name}", master_value(name, None), lease, revision, revision)


def old_store_view(clock: Clock) -> View:
    """a's view of a store at revision 480: b holds l0, a holds l1 (put by a at 470)."""
    view = View("/t", "a", clock)
    assert view.read_from(CLUSTER, 460) is None
    view.load(460, [line("l0", "b", 0xB1, 400)], [instance("a", 0xA0, 10), instance("b", 0xB0, 11)])
    view.held_by("l1", Master("a", None), 0xA1, 470)
    view.apply([Event(line("l2", "b", 0xB1, 480), deleted=False)])
    return view


def test_the_same_store_read_again_keeps_the_view() -> None:
    clock = Clock()
    view = old_store_view(clock)
    assert view.read_from(CLUSTER, 480) is None
    assert view.read_from(CLUSTER, 500) is None
    assert set(view.holders) == {"l0", "l1", "l2"} and view.revision == 480


def test_a_store_whose_revision_went_back_is_read_anew() -> None:
    clock = Clock()
    view = old_store_view(clock)
    clock.now = 130.0
    assert view.read_from(CLUSTER, 7) == "revision went back from 480 to 7"
    assert view.holders == {} and view.changed_at == {} and view.instances == {}
    assert view.free_since == {} and view.revision == 0 and not view.fresh
    # the new store's keys, all at revisions below the old ones, are taken
    view.load(7, [line("l1", "b", 0x2B, 6)], [instance("b", 0x2C, 3)])
    assert view.holders["l1"].master == Master("b", None) and view.lease_of("l1") == 0x2B
    assert view.free("l0") and view.free("l2") and set(view.instances) == {"b"}
    view.apply([Event(line("l0", "a", 0x2A, 8), deleted=False)])
    view.apply([Event(line("l1", "b", 0x2B, 9), deleted=True)])
    assert view.lease_of("l0") == 0x2A and view.free("l1") and view.free_since["l1"] == 130.0
    assert view.read_from(CLUSTER, 9) is None  # and it is the store from now on
    assert view.read_from(CLUSTER, 8) == "revision went back from 9 to 8"


def test_without_the_check_the_old_revisions_hide_the_new_store() -> None:
    """Why the check matters: a load alone keeps what it knows of keys changed later."""
    view = old_store_view(Clock())
    view.load(7, [line("l1", "b", 0x2B, 6)], [instance("b", 0x2C, 3)])
    assert view.holders["l1"].master == Master("a", None)  # a's, from the old store


def test_another_cluster_is_another_store_whatever_its_revision() -> None:
    view = old_store_view(Clock())
    assert view.read_from("77", 9000) == f"cluster id changed from {CLUSTER} to 77"
    assert view.holders == {} and view.cluster_id == "77" and view.revision == 0
    assert view.read_from("77", 9000) is None
