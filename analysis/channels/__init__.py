"""What the measuring channels add to a run: time base, lag, transients, torque zero."""
