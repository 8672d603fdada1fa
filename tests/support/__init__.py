"""Helpers shared by the tests: a throw-away PostgreSQL server, the page tests' shared
simulated rig, simulated transmission error runs."""
