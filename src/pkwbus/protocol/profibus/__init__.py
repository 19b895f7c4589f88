"""PROFIBUS, sans I/O: FDL frames and timing, DP services and the slave's state machine,
PPOs, DP-V1 record transfer, and GSD files."""

__all__: list[str] = []
