"""`motorlab tune`: an Optuna search over a command's or recipe's settings, each trial judged
over several seeds (the IQM; steps to success: censored at the budget), with pruning, a resumable shared study, and a fresh-seed check.

    space.py      --space KEY=DIST: loguniform, uniform, int, choice
    objective.py  the number per seed (summary.json) and the intermediate numbers (metrics.csv)
    trials.py     a trial's seeds as the sweep's trial processes, watched while they run
    search.py     the study (storage, sampler, pruner) and the trial loop
    ray_search.py --backend ray: the same search through Ray Tune (OptunaSearch, ASHA) on a cluster;
                  ray_study.py its searcher and scheduler (driver), ray_trial.py its trainable (workers)
    outputs.py    trials.csv, the table, best.toml, plots
    tune.py       motorlab tune: the above, then the best settings on fresh seeds
"""
