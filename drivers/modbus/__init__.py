"""Modbus TCP/RTU drivers: the link, the register map and the torque sensor (the loading
drive is drivers/loading_drive.py)."""
