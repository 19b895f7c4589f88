"""Schemathesis against the OpenAPI schema of the running service: no 5xx, ever.

The service (simulators, runtime, app) runs in its own event loop in a
thread, served by uvicorn on a loopback port; schemathesis generates
requests from the schema (valid and invalid ones) and sends them over HTTP.
Some path parameters and the token are swapped for real ones, so that the
requests also reach the checks and the bus, not only the 404 and 401 paths.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import hypothesis
import pytest
import requests
import schemathesis
from hypothesis import strategies as st
from schemathesis.checks import not_a_server_error

from tests.service.http.conftest import AUTH, USS_DRIVES
from tests.service.http.threaded import served_in_thread

BUDGET = 45.0  # seconds for the whole run, checked as it goes
DRIVES = [None, "fan1", "fan2", "pump1"]
PARAMETERS = [None, "3-41", "3-42", "1-20", "16-13", "15-30", "15-30[3]", "p1120", "r0021"]
# Values every writable parameter here holds exactly (writes refuse what they would
# round), so that some generated writes can succeed; None keeps the generated value.
VALUES = [None, 5, 10, 20.5, 500]


AUTH_TOKEN = AUTH["Authorization"].removeprefix("Bearer ")


@pytest.mark.long
def test_no_server_errors(tmp_path: Path) -> None:
    with served_in_thread(tmp_path, AUTH_TOKEN, uss=USS_DRIVES) as svc:
        schema = schemathesis.openapi.from_dict(svc.app.openapi())
        operations = [result.ok() for result in schema.get_all_operations()]
        assert {op.path for op in operations} >= {
            "/api/v1/drives/{drive}/parameters/{parameter}",
            "/api/v1/audit",
            "/healthz",
        }
        session = requests.Session()
        deadline = time.monotonic() + BUDGET
        seen: dict[str, set[int]] = {}
        for op in operations:
            for mode in (
                schemathesis.GenerationMode.POSITIVE,
                schemathesis.GenerationMode.NEGATIVE,
            ):
                check = make_check(op, mode, svc.url, session, deadline, seen)
                try:
                    check()
                except hypothesis.errors.Unsatisfiable:
                    # nothing in the operation can be made invalid (GET /healthz)
                    assert mode is schemathesis.GenerationMode.NEGATIVE
        print(
            f"\n{time.monotonic() - deadline + BUDGET:.1f} s; statuses seen:",
            {k: sorted(v) for k, v in seen.items()},
        )
        assert svc.error is None
        put = seen["PUT /api/v1/drives/{drive}/parameters/{parameter}"]
        assert {200, 401, 403, 404, 422} <= put, put
        assert time.monotonic() < deadline + 30


def make_check(
    op: Any,
    mode: schemathesis.GenerationMode,
    url: str,
    session: requests.Session,
    deadline: float,
    seen: dict[str, set[int]],
) -> Any:
    name = f"{op.method.upper()} {op.path}"

    @hypothesis.settings(
        max_examples=300 if op.method.upper() == "PUT" else 25,
        deadline=None,
        database=None,
        derandomize=True,
        suppress_health_check=list(hypothesis.HealthCheck),
        phases=[hypothesis.Phase.generate],
    )
    @hypothesis.given(
        case=op.as_strategy(mode),
        drive=st.sampled_from(DRIVES),
        parameter=st.sampled_from(PARAMETERS),
        authed=st.booleans(),
        value=st.sampled_from(VALUES),
    )
    def check(
        case: Any, drive: str | None, parameter: str | None, authed: bool, value: float | None
    ) -> None:
        if time.monotonic() > deadline:
            return
        if case.path_parameters is not None:
            if drive and "drive" in case.path_parameters:
                case.path_parameters["drive"] = drive
            if parameter and "parameter" in case.path_parameters:
                case.path_parameters["parameter"] = parameter
        if value is not None and isinstance(case.body, dict) and "value" in case.body:
            case.body["value"] = value
        headers = {"Authorization": f"Bearer {AUTH_TOKEN}"} if authed else None
        response = case.call(base_url=url, session=session, headers=headers, timeout=30)
        seen.setdefault(name, set()).add(response.status_code)
        case.validate_response(response, checks=[not_a_server_error])

    return check
