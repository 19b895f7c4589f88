"""The bus master: drives as targets, PKW transactions, lines, the scheduler."""

__all__: list[str] = []
