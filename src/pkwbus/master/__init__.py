"""The bus master of FC, USS and PROFIBUS DP lines: drives as targets, PKW transactions,
the planner, the lines and their wires, and the one runner that drives every kind of line."""

__all__: list[str] = []
