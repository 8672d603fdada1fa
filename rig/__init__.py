"""backlash-rig application: run format, sequencer, campaigns, store, CLI and web page."""

__version__ = "0.1.0"
