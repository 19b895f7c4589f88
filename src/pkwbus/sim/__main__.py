"""``python -m pkwbus.sim``: the same as ``pkwbus simulate``."""

import sys

from pkwbus.sim.cli import main

sys.exit(main())
