"""PROFIBUS DP-V1: MSAC_C1 record reads and writes between the cyclic exchanges."""

__all__: list[str] = []
