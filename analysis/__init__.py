"""Pure numerics over numpy arrays: hysteresis loop metrics, gear models, effects, diagnosis.

Nothing here does I/O or talks to devices; nothing here imports `rig`, `drivers` or `simulators`.
"""
