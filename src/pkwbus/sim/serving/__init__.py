"""How the simulated drives and slaves are served: on a pseudo-terminal or TCP."""

__all__: list[str] = []
