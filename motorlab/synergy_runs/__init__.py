"""Synergies of trained runs: the activations (or commands) a policy's rollouts record, which a
synergy fit starts from; ablations of a SAR policy's synergies; the figures of a fit and the names of
its signals. Above the domain packages it rolls out (evaluation, policies, envs) and the synergy space
it fits in (motorlab.synergies)."""
