"""pkwbus: an RS-485 bus master for the PKW parameter channel of drives on Danfoss FC,
Siemens USS and PROFIBUS DP lines."""

__all__ = ["__version__"]

__version__ = "0.1.0"
