"""TQC (sb3-contrib): SAC with distributional critics whose highest quantiles are dropped, which
curbs SAC's overestimation. Off-policy, continuous actions, takes --her; its actor is SAC's, so its
policy acts and deploys (ONNX) as SAC's does."""

from motorlab.algos.base import OffPolicy

ALGORITHM = OffPolicy(
    name="tqc",
    title="TQC",
    summary="Truncated Quantile Critics (sb3-contrib), off-policy; Box actions",
    cls="sb3_contrib:TQC",
    networks={"TQCPolicy": "sb3_contrib.tqc.policies:TQCPolicy",
              "TQCMultiInputPolicy": "sb3_contrib.tqc.policies:MultiInputPolicy"},
    zip_modules=("sb3_contrib.tqc.policies",),
)
