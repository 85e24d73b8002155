"""Sweeps: seeds × settings of one command or recipe, on a local process pool or a Ray cluster,
aggregated with rliable (IQM and stratified-bootstrap confidence intervals).

    grid.py      --grid key=v1,v2: the settings to try
    trials.py    a target read once into settings; one trial = one job writing one run folder
                 (motorlab/launcher.py starts them: a local pool of processes, or Ray Tune)
    stats.py     IQM, bootstrap CIs, probability of improvement, performance profiles
    sweep.py     motorlab sweep: the above, then summary.json, plots and report.html
"""
