"""``python -m simlan_data`` runs the default scenario (same as ``python -m simlan_data.run``)."""

from simlan_data.apps.signals import exit_on_early_signal

exit_on_early_signal()  # SIGTERM while the app is imported: one line, exit 143

from simlan_data.apps.run import main  # noqa: E402

main()
