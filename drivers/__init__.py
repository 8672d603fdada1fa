"""Device drivers: CANopen encoder (CiA 406), serial ASCII torque transducer, Modbus devices."""
