from motorlab.processes import unblock

# Ray's workers block SIGINT, and a process they start inherits the blocked mask: a trial that
# `motorlab sweep`/`tune --backend ray` runs would never see the Ctrl-C that stops it early
# (motorlab.sweeps.backends._stop) and would be killed after a grace period instead. The same
# for SIGTERM and SIGHUP, which stop a command as Ctrl-C does (motorlab.processes).
unblock()

from motorlab.cli import main  # noqa: E402 - after the mask, so Ctrl-C works during the (slow) imports too

main()
