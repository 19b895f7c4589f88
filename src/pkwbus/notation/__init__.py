"""How a person writes a value: durations (``100ms``), host and port, limits and ranges, the
problems of a value said in words, and the YAML files they are written in. The
configuration, the command line and the simulator read values through here."""

__all__: list[str] = []
