"""``python -m pkwbus.sim``: the same as ``pkwbus simulate``."""

import sys

from pkwbus.sim.cli import main

__all__: list[str] = []

sys.exit(main())
