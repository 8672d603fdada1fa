"""The simulated rig's in-process CAN wiring (python-can's virtual bus, made cheaper)."""
