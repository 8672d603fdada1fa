"""``python -m rig`` runs the ``rig`` command line."""

from rig.cli import main

main()
