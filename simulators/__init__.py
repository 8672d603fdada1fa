"""Simulated devices: the plant model, protocol faces over the real wire protocols, a backdoor."""
