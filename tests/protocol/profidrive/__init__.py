"""profidrive."""

__all__: list[str] = []
