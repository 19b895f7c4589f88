"""Sans-I/O implementation of the FC and USS telegrams, the PROFIBUS DP frames and
services, and the PKW channel they carry.

Bytes in, objects out: nothing here reads a clock, a port or an event loop.
"""

__all__: list[str] = []
