"""The test suite (folders mirror the packages: analysis, drivers, simulators, rig/<package>)."""
