"""The long-running service around the bus master, in rooms by capability: the
configuration file (:mod:`.config`), what ``/metrics`` shows (:mod:`.metrics`), the
audit log (:mod:`.audit`), the HTTP API (:mod:`.http`), and how ``pkwbus run`` puts
them together (:mod:`.assembly`); :mod:`.runtime` is the running service's object
graph they share. Each room imports only those listed before it, and runtime."""

__all__: list[str] = []
