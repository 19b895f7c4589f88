"""Sans-I/O implementation of the FC and USS telegrams and the PKW channel.

Bytes in, objects out: nothing here reads a clock, a port or an event loop.
"""

__all__: list[str] = []
