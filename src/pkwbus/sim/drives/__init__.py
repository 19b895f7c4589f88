"""drives."""

__all__: list[str] = []
