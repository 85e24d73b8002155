"""CrossQ (sb3-contrib): SAC without target networks, with batch renormalization in actor and
critics, for more updates' worth of learning per env step. Off-policy, continuous actions.

sb3-contrib gives it no policy for Dict observations, so it trains on Box observations only,
and so takes no --her (HER needs the Dict of goals). Its actor's batch-renormalization layers act
on their running statistics once the network is in eval mode, as every saved policy is.
"""

from motorlab.algos.base import OffPolicy, Preset

ALGORITHM = OffPolicy(
    name="crossq",
    title="CrossQ",
    summary="CrossQ (sb3-contrib): SAC without target networks, batch-renormalized; off-policy; Box actions "
            "and observations",
    cls="sb3_contrib:CrossQ",
    multi_input_policy=None,
    her=False,
    networks={"CrossQPolicy": "sb3_contrib.crossq.policies:CrossQPolicy"},
    zip_modules=("sb3_contrib.crossq.policies",),
    presets={
        # CrossQ (Bhatt et al. 2024) at one gradient step per env step, as published, with the SAR study's
        # normalization, buffer and discount, and critics of [512, 512] instead of its [1024, 1024]: at
        # ~4x fewer FLOPs an update, its few updates an hour of one core count for more (a contender of
        # benchmarks/learner_per_hour.py)
        "sar-crossq": Preset(
            "CrossQ for muscle tasks on a small machine: one update per env step, [256, 256] actor, "
            "[512, 512] critics",
            {"normalize": True,
             "hyperparams": {"buffer_size": 300_000, "learning_starts": 1000, "batch_size": 256, "gamma": 0.98,
                             "policy_kwargs": {"net_arch": {"pi": [256, 256], "qf": [512, 512]}}}}),
    },
)
