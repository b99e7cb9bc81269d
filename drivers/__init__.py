"""flagtrack drivers: event files, camera adapters, wind-tunnel drivers and the digital twin."""
