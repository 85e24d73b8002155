"""Sweeps: seeds × settings of one command or recipe, on a local process pool or a Ray cluster,
aggregated with rliable (IQM and stratified-bootstrap confidence intervals).

    grid.py      --grid key=v1,v2: the settings to try
    trials.py    one trial = one motorlab command line writing one run folder; resume markers
    backends.py  where trials run: local (a pool of processes) or ray (Ray Tune)
    stats.py     IQM, bootstrap CIs, probability of improvement, performance profiles
    sweep.py     motorlab sweep: the above, then summary.json, plots and report.html
"""
