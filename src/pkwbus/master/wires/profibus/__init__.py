"""The PROFIBUS DP wire: one Data_Exchange per slave per cycle, DP-V1 between, the live
list, and the FDL port under them."""

__all__: list[str] = []
