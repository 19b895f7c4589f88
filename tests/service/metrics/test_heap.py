"""pkwbus run puts what start-up made out of the cyclic garbage collector's sight."""

from __future__ import annotations

import gc

from pkwbus.service.assembly.serve import settle_heap


def test_start_up_objects_leave_the_collectors_generations_and_later_ones_do_not() -> None:
    made_at_start = [[index] for index in range(100)]
    try:
        settle_heap()
        watched = {id(o) for o in gc.get_objects()}
        assert not any(id(item) in watched for item in made_at_start)
        assert gc.get_freeze_count() >= len(made_at_start)
        made_later = [[index] for index in range(3)]
        watched = {id(o) for o in gc.get_objects()}
        assert all(id(item) in watched for item in made_later)
    finally:
        gc.unfreeze()
        gc.collect()  # what was frozen and is garbage goes now, not in a later test
