"""rover-sitl: a skid-steer rover emulator on a MAVLink link (behaves like ArduPilot Rover in MANUAL)."""
