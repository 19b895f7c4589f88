"""Simulated FC and USS drives: their parameters, a motor model, faults and logs."""

__all__: list[str] = []
