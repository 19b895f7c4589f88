"""What ``/metrics`` shows: the service's own counters (:mod:`.instrumentation`), the
drives' values read from the snapshot (:mod:`.devices`), and the Prometheus text
format they are rendered in, a series at a time and cached (:mod:`.exposition`).
Nothing here causes bus traffic, and nothing here knows HTTP, the audit log or the
configuration file."""

__all__: list[str] = []
