"""The JSON log's ``logger`` field says where a line comes from, and log pipelines
filter on it: the service's modules keep the logger names they were published with,
wherever the module itself lives."""

from __future__ import annotations

import importlib
import json
import logging

import pytest

from pkwbus.service.assembly.logs import JsonFormatter

LOGGERS = {
    "pkwbus.service.assembly.root": "pkwbus",
    "pkwbus.service.assembly.serve": "pkwbus.service.app",
    "pkwbus.service.audit.log": "pkwbus.service.audit",
    "pkwbus.service.audit.writer": "pkwbus.service.recorder",
    "pkwbus.service.http.connections": "pkwbus.service.http",
    "pkwbus.service.runtime": "pkwbus.service.runtime",
}


@pytest.mark.parametrize("module", sorted(LOGGERS))
def test_a_module_logs_under_its_published_name(module: str) -> None:
    log = importlib.import_module(module).log
    assert isinstance(log, logging.Logger)
    record = log.makeRecord(log.name, logging.INFO, module, 1, "a line", (), None)
    assert json.loads(JsonFormatter().format(record))["logger"] == LOGGERS[module]
