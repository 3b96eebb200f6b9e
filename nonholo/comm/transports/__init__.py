"""Transports: one small interface (``Transport``) over in-process queues, TCP, Bluetooth
RFCOMM and, optionally, Zenoh. Import the concrete modules directly; Zenoh is imported
only by ``nonholo.comm.transports.zenoh``."""
from nonholo.comm.transports.base import Capabilities, Transport, TransportClosed, UnknownPeer

__all__ = ["Capabilities", "Transport", "TransportClosed", "UnknownPeer"]
