"""multiarm_pin."""
