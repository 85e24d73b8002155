"""Forward models: collect transitions (closed form, MuJoCo rollouts or Gymnasium envs), fit a
normalized-delta ensemble in torch, check it open loop against the simulator."""
