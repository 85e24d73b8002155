"""CrossQ (sb3-contrib): SAC without target networks, with batch renormalization in actor and
critics, for more updates' worth of learning per env step. Off-policy, continuous actions.

sb3-contrib gives it no policy for Dict observations, so it trains on Box observations only,
and so takes no --her (HER needs the Dict of goals). Its actor's batch-renormalization layers act
on their running statistics once the network is in eval mode, as every saved policy is.
"""

from motorlab.rl.algos.base import OffPolicy

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
)
