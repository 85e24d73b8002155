"""SAC (Stable-Baselines3): off-policy, continuous actions, takes --her; the SAR study's presets."""

from motorlab.algos.base import OffPolicy, Preset

# The reference SAC settings of the SAR study (MyoSuite, Berg et al. 2023): play phase.
SAR_SAC = {
    "lr": "linear:1e-3,0",
    "normalize": True,  # VecNormalize observations, clip 10
    "hyperparams": {
        "policy_kwargs": {"net_arch": {"pi": [400, 300], "qf": [400, 300]}},
        "buffer_size": 300_000, "learning_starts": 1000, "batch_size": 256, "tau": 0.02, "gamma": 0.98,
        "train_freq": [1, "episode"], "gradient_steps": -1,
    },
}

ALGORITHM = OffPolicy(
    name="sac",
    title="SAC",
    summary="Soft Actor-Critic (Stable-Baselines3), off-policy; Box actions",
    cls="stable_baselines3:SAC",
    networks={"SACPolicy": "stable_baselines3.sac.policies:SACPolicy",
              # SAC's and TD3's multi-input classes are both called MultiInputPolicy: named by algorithm
              "SACMultiInputPolicy": "stable_baselines3.sac.policies:MultiInputPolicy"},
    zip_modules=("stable_baselines3.sac.policies",),
    presets={
        "sar-sac": Preset("the SAR study's reference SAC (MyoSuite, Berg et al. 2023), play phase", SAR_SAC),
        "sb3-sac": Preset("Stable-Baselines3's SAC defaults, named so recipes can say so", {"hyperparams": {}}),
        # Training in synergy space uses the same settings with a longer warm-up.
        "sar-sac-synergy": Preset("sar-sac with a 5000-step warm-up, for training in synergy space",
                                  {**SAR_SAC, "hyperparams": {**SAR_SAC["hyperparams"], "learning_starts": 5000}}),
        # The reference at fewer gradient steps per env step (one every k env steps), and with smaller
        # networks: the contenders of benchmarks/learner_per_hour.py, which measures which learns most
        # in an hour of one core.
        **{f"sar-sac-{name}": Preset(f"sar-sac with one gradient step per {k} env steps",
                                     {**SAR_SAC, "hyperparams": {**SAR_SAC["hyperparams"], "train_freq": [k, "step"],
                                                                 "gradient_steps": 1}})
           for name, k in (("half", 2), ("quarter", 4), ("eighth", 8))},
        "sar-sac-256": Preset("sar-sac with [256, 256] networks (~half the FLOPs of an update)",
                              {**SAR_SAC, "hyperparams": {**SAR_SAC["hyperparams"],
                                                          "policy_kwargs": {"net_arch": {"pi": [256, 256],
                                                                                         "qf": [256, 256]}}}}),
        # The reference SAC with what a 2-core CPU can afford: the same networks, learning rate,
        # buffer, batch, tau, gamma and normalization, four env processes, and one gradient step
        # per 25 env steps instead of one per env step. An update of the [400, 300] nets on a
        # 256 batch is ~2 GFLOP, so one update per env step caps the reference at the rate of
        # updates a core does (benchmarks/learner_per_hour.py and sar_study.py measure both
        # learners' rates and what they learn: results/learner_per_hour.json, sar_study.json;
        # docs/benchmarks.md). It learns less per env step than the reference, and more per
        # wall-clock minute: the learner the SAR recipes use.
        "sar-sac-fast": Preset(
            "sar-sac for a 2-core CPU: 4 env processes, 4 gradient steps every 25 vectorized steps",
            {**SAR_SAC,
             "n_envs": 4,         # more steps per policy call and per pipe round trip; 2 per core
             "torch_threads": 2,  # the envs wait while the networks train
             # SB3 counts train_freq in vectorized steps: every 25 x 4 env steps, 4 gradient steps
             "hyperparams": {**SAR_SAC["hyperparams"], "train_freq": 25, "gradient_steps": 4}}),
    },
)
