"""Point sensors (a laser distance sensor across the flag): interface, serial ASCII and Modbus RTU
drivers, a simulated device on a pseudo-terminal, and a simulated sensor that reads the digital twin.

See docs/sensor.md. :func:`~flagtrack.drivers.sensor.setup.open_sensor` opens the sensor of a
``sensor:`` config section.
"""
