"""How ``pkwbus run`` puts the service together and takes it apart: the composition
root (:mod:`.root`: logging, audit log, HTTP address, runtime, app, in that order),
the runtime built from a configuration (:mod:`.build`, with each drive's parameters
resolved once by :mod:`.parameter_table`), the service running from start to stop
under its signals (:mod:`.serve`), and its log lines' format (:mod:`.logs`). The
other rooms know nothing of it; it alone knows them all."""

__all__: list[str] = []
