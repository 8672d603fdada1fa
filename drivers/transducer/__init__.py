"""The serial ASCII torque transducer: its protocol (pure parsing) and the serial driver."""
