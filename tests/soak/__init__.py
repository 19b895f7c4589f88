"""The soak: ``pkwbus run`` for an hour (``make soak``) or four minutes (``make test-long``)
against simulated lines with faults, lost ports and restarting slaves; see run.py."""
