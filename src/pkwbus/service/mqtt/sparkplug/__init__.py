"""Sparkplug B (``mqtt.sparkplug: {group_id, edge_node_id}``): pkwbus as an edge node of
the Eclipse Sparkplug 3.0.0 specification, each drive a device. The payload's codec
(:mod:`.codec`, by hand on the protobuf wire format), the births' metrics from the
catalog (:mod:`.metrics`), the node (:mod:`.node`: its own connection with NDEATH as
the will, NBIRTH/DBIRTH, DDATA by exception, DDEATH, rebirth), a DCMD's writes through
the one write path (:mod:`.commands`), the ``bdSeq`` kept across restarts and the
primary host's STATE (:mod:`.host`); :mod:`.attach` makes it one of the service's
outputs."""

__all__: list[str] = []
