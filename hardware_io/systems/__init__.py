"""Drake systems that bridge real hardware (serial ports, sockets) into a diagram."""

from hardware_io.systems.gps_serial_source import GpsSerialSource, GpsSerialStatus

__all__ = ["GpsSerialSource", "GpsSerialStatus"]
