"""The commands over PROFIBUS DP: the master's context for one slave, and the live list scan."""

__all__: list[str] = []
