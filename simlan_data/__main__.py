"""``python -m simlan_data`` runs the default scenario (same as ``python -m simlan_data.run``)."""

from simlan_data.apps.run import main

main()
