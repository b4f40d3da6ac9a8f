"""The light transport of the training views, recorded once (`record`) and applied as a torch operator
(`operator`): a data term without path tracing; `settings` holds how it is recorded."""

from dpi.solve.transport.operator import AlbedoLookup, LightTransport, NormalEquations, resize_map
from dpi.solve.transport.record import guide_map, record_transport, record_view
from dpi.solve.transport.settings import MAX_TRANSPORT_HEIGHT, ROUGH_TRANSPORT_HEIGHT, TransportConfig, transport_height

__all__ = ["MAX_TRANSPORT_HEIGHT", "ROUGH_TRANSPORT_HEIGHT", "AlbedoLookup", "LightTransport", "NormalEquations",
           "TransportConfig", "guide_map", "record_transport", "record_view", "resize_map",
           "transport_height"]
