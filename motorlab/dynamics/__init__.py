"""Forward models: collect transitions (closed form, MuJoCo rollouts or Gymnasium envs), fit a
normalized-delta ensemble in torch, check it open loop against the simulator.

The Python API's steps are `motorlab.api.dynamics`:

    from motorlab.api import dynamics
    model = dynamics.fit(dynamics.collect("Reacher-v5", 5000))
    dynamics.check(model, episodes=5)
"""
