"""pkwbus: an RS-485 bus master for the PKW parameter channel of FC and USS drives."""

__all__ = ["__version__"]

__version__ = "0.1.0"
