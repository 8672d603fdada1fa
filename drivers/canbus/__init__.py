"""The CAN link under the encoders: how python-can's SLCAN bus reads its serial port."""
