"""flagtrack calibration: blinking-checkerboard pixel-to-plane mapping."""
