"""The FC and USS wire: one telegram exchange at a time on an RS-485 port."""

__all__: list[str] = []
