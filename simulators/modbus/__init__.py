"""The simulated Modbus devices (loading drive, torque sensor) on a pymodbus server, with a
backdoor for injected faults and a test plant."""
