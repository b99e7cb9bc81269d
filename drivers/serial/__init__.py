"""Serial links shared by the tunnel and the point-sensor drivers: the byte adapter (pyserial),
Modbus RTU framing, and pseudo-terminal links for simulated devices."""
