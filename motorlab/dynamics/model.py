"""Forward model: (state, action) -> next state, learned as a normalized state delta.

The network is an MLP, optionally an ensemble of K such nets, with one of two nonlinearities:
- "silu" (the default): Linear -> SiLU (swish) per hidden layer, no normalization, as PETS' and
  mbrl-lib's ensembles;
- "tanh": the reference notebook's (10 -> 64 Tanh LayerNorm -> 64 Tanh LayerNorm -> 8 for Reacher),
  motorlab's only choice before SiLU was measured (model.json files without "nonlinearity" are it).
Why SiLU: a saturating tanh (with or without the layer norm) fits a body's response to larger
actions and faster motions poorly. On the same 3,000 transitions of a Reacher loop (seed 1, 200
epochs, 5 probabilistic members, [64, 64]), the held-out MSE of the normalized delta was 1.42 with
tanh + LayerNorm, 1.47 with tanh alone, 0.83 with ReLU, 0.52 with SiLU, and MPC on them returned
-5.68, -5.77, -5.43, -5.18 on the same 10 episodes (the true simulator's MPC: -4.59): tanh's models
under-predicted how far the arm swings under the planner's harder actions, so it accelerated
timidly and overshot. With plenty of data they plan alike: on 20,000 random Reacher episodes
(benchmarks/mpc.py's pipeline, deterministic, one member) MPC returned -3.66 (tanh) and -3.68
(SiLU) over 50 episodes, SiLU's held-out error 0.0023 against 0.0031, its fit 90 s against 133 and
its plan 5.0 ms against 6.2.

The K members are stored as stacked weights and run as batched matmuls (`torch.baddbmm`), so an
ensemble costs one pass, not K. Saved as `model.safetensors` (weights, normalizer statistics) + `model.json`
(architecture, state layout, env id, metrics): no pickle.

Two options make it the model of PETS (Chua et al. 2018) and of mbrl-lib:
- `probabilistic`: each member predicts a Gaussian (mean and log-variance of the normalized
  delta), trained by Gaussian NLL; the log-variance is kept between learned bounds
  (`max_logvar`, `min_logvar`, soft-clamped as in PETS) so it cannot run away off the data.
- `heads`: "reward" (the step's reward, fitted with the dynamics, for envs without a torch
  reward) and "termination" (a classifier's logit: did the step end the episode).
Output columns per member: [delta (S), reward (1)] means, then their log-variances when
probabilistic, then the termination logit.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from motorlab.dynamics.transitions import check_meta
from motorlab.errors import MotorlabError
from motorlab.runs import atomic_write_bytes, read_json, recall_imports, write_json

MODEL_JSON = "model.json"
MODEL_WEIGHTS = "model.safetensors"
FORMAT = "motorlab.forward_model/1"
NONLINEARITIES = ("silu", "tanh")  # tanh: Linear -> Tanh -> LayerNorm; silu: Linear -> SiLU (see the module's docstring)
DEFAULT_NONLINEARITY = "silu"  # the Python API's default, as the CLI's (motorlab.kinds.dynamics.ModelSettings)


class Normalizer(nn.Module):
    """x -> (x - mean) / std with fixed statistics (std floored so constant entries stay finite)."""

    def __init__(self, size: int):
        super().__init__()
        self.register_buffer("mean", torch.zeros(size))
        self.register_buffer("std", torch.ones(size))

    def fit(self, x: np.ndarray | torch.Tensor) -> Normalizer:
        x = torch.as_tensor(x, dtype=torch.float64)
        self.mean.copy_(x.mean(0))
        self.std.copy_(x.std(0).clamp_min(1e-6))
        return self

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean) / self.std

    def inverse(self, z: torch.Tensor) -> torch.Tensor:
        return z * self.std + self.mean


LN_EPS = 1e-5  # nn.LayerNorm's default


def tanh_layer_norm(x: torch.Tensor) -> torch.Tensor:
    """layer_norm(tanh(x)) (no affine), computed as layer_norm(sigmoid(2x)) with eps/4.

    tanh(x) = 2 sigmoid(2x) - 1, and layer norm ignores a positive scale and a shift of its
    input once eps is scaled by 1/4 (the variance scales by 4), so the two are the same
    function. Why: torch's CPU tanh is ~4x slower than its sigmoid (measured 14.8 vs 3.9 us
    on 80x64 floats), and tanh is the bulk of a small forward pass.
    """
    return F.layer_norm(torch.sigmoid(2 * x), x.shape[-1:], eps=LN_EPS / 4)


class EnsembleMLP(nn.Module):
    """K independent MLPs (Linear -> Tanh -> LayerNorm, or Linear -> SiLU, per hidden layer), evaluated
    together.

    Input (K, B, n_in) or (B, n_in) (shared by all members); output (K, B, n_out).
    """

    def __init__(self, n_in: int, n_out: int, hidden: tuple[int, ...] = (64, 64), members: int = 1,
                 nonlinearity: str = DEFAULT_NONLINEARITY):
        super().__init__()
        if nonlinearity not in NONLINEARITIES:
            raise MotorlabError(f"unknown nonlinearity {nonlinearity!r}; choose {' or '.join(NONLINEARITIES)}.")
        sizes = (n_in, *hidden, n_out)
        self.members = members
        self.nonlinearity = nonlinearity
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for a, b in zip(sizes[:-1], sizes[1:]):
            bound = 1 / math.sqrt(a)  # nn.Linear's default initialization, per member
            self.weights.append(nn.Parameter(torch.empty(members, a, b).uniform_(-bound, bound)))
            self.biases.append(nn.Parameter(torch.empty(members, 1, b).uniform_(-bound, bound)))
        normed = hidden if nonlinearity == "tanh" else ()  # only tanh's layers have a layer norm (and its affine)
        self.ln_weights = nn.ParameterList([nn.Parameter(torch.ones(members, 1, h)) for h in normed])
        self.ln_biases = nn.ParameterList([nn.Parameter(torch.zeros(members, 1, h)) for h in normed])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() == 2:
            x = x.expand(self.members, *x.shape)
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            x = torch.baddbmm(b, x, w)
            if i < last:
                x = (tanh_layer_norm(x) * self.ln_weights[i] + self.ln_biases[i] if self.nonlinearity == "tanh"
                     else F.silu(x))
        return x


def _hidden_and_out(x: torch.Tensor, layers, norms) -> torch.Tensor:
    """The rest of a planning pass after the first layer's pre-activation x: tanh_layer_norm with
    its 2x already folded into the weights (so layer_norm(sigmoid(.))), then the next layer; with
    `norms` None (silu), SiLU, then the next layer."""
    if norms is None:
        for w, b in layers:
            x = torch.addmm(b, F.silu(x), w)
        return x
    for (w, b), (lw, lb) in zip(layers, norms):
        x = torch.addmm(b, F.layer_norm(torch.sigmoid(x), lw.shape, lw, lb, LN_EPS / 4), w)
    return x


def _hidden(x: torch.Tensor, nonlinearity: str) -> torch.Tensor:
    """A planning layer's nonlinearity on its pre-activation (K, N, h): tanh's as layer_norm(sigmoid(.))
    (its 2x folded into the weights, the layer norm's affine into the next layer), or SiLU."""
    return F.silu(x) if nonlinearity == "silu" else F.layer_norm(torch.sigmoid(x), x.shape[-1:], eps=LN_EPS / 4)


def stepwise_rollout(predict):
    """Open-loop paths (N, H+1, S) of states (N, S) under actions (N, H, A) from a one-step predict."""
    def rollout(states: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        path = [states]
        for t in range(actions.shape[1]):
            path.append(predict(path[-1], actions[:, t]))
        return torch.stack(path, 1)
    return rollout


HEADS = ("reward", "termination")


def device_for(name: str = "auto") -> torch.device:
    """The torch device NAME ("auto": the GPU where torch sees one, else the CPU).

    Raises:
        MotorlabError: a device torch does not have here.
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except RuntimeError:
        raise MotorlabError(f"--device {name!r} is not a torch device; use auto, cpu or cuda[:N].") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise MotorlabError(f"--device {name}: torch sees no CUDA GPU here (this torch build: "
                            f"{torch.__version__}); use --device auto or cpu.")
    return device


class ForwardModel(nn.Module):
    """next_state = state + delta_norm.inverse(net([state_norm(s), action_norm(a)]))."""

    def __init__(self, state_size: int, action_size: int, hidden: tuple[int, ...] = (64, 64), members: int = 1,
                 meta: dict[str, Any] | None = None, probabilistic: bool = False, heads: tuple[str, ...] = (),
                 nonlinearity: str = DEFAULT_NONLINEARITY):
        super().__init__()
        unknown = set(heads) - set(HEADS)
        if unknown:
            raise MotorlabError(f"unknown model heads {sorted(unknown)}; choose from {', '.join(HEADS)}.")
        self.state_size, self.action_size, self.hidden = state_size, action_size, tuple(hidden)
        self.probabilistic = bool(probabilistic)
        self.heads = tuple(h for h in HEADS if h in heads)
        self.state_norm = Normalizer(state_size)
        self.action_norm = Normalizer(action_size)
        self.delta_norm = Normalizer(state_size)
        self.reward_norm = Normalizer(1)
        self.gaussian = state_size + (1 if "reward" in self.heads else 0)  # the columns with a mean (and variance)
        n_out = self.gaussian * (2 if self.probabilistic else 1) + (1 if "termination" in self.heads else 0)
        self.net = EnsembleMLP(state_size + action_size, n_out, self.hidden, members, nonlinearity)
        if self.probabilistic:  # PETS' learned bounds on the log-variance (normalized units), per member
            self.max_logvar = nn.Parameter(torch.full((members, 1, self.gaussian), 0.5))
            self.min_logvar = nn.Parameter(torch.full((members, 1, self.gaussian), -10.0))
        self.meta = dict(meta or {})

    @property
    def members(self) -> int:
        return self.net.members

    @property
    def nonlinearity(self) -> str:
        return self.net.nonlinearity

    @property
    def plain(self) -> bool:
        """Deterministic state-only members."""
        return not self.probabilistic and not self.heads

    def fit_normalizers(self, states, actions, next_states, rewards=None) -> None:
        self.state_norm.fit(states)
        self.action_norm.fit(actions)
        self.delta_norm.fit(np.asarray(next_states) - np.asarray(states))
        if rewards is not None:
            self.reward_norm.fit(np.asarray(rewards).reshape(-1, 1))

    def bounded_logvar(self, raw: torch.Tensor) -> torch.Tensor:
        """PETS' soft clamp of raw log-variances (K, B, G) between the learned bounds."""
        logvar = self.max_logvar - F.softplus(self.max_logvar - raw)
        return self.min_logvar + F.softplus(logvar - self.min_logvar)

    def split(self, out: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
        """A member's raw output (..., n_out) as (mean (..., G), log-variance (..., G) or None,
        termination logit (...,) or None), in normalized units."""
        g = self.gaussian
        mean = out[..., :g]
        logvar = self.bounded_logvar(out[..., g:2 * g]) if self.probabilistic else None
        logit = out[..., -1] if "termination" in self.heads else None
        return mean, logvar, logit

    def inputs(self, states: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.state_norm(states), self.action_norm(actions)], dim=-1)

    @torch.no_grad()
    def training_pairs(self, states, actions, next_states, rewards=None) -> tuple[torch.Tensor, torch.Tensor]:
        """The net's inputs and Gaussian targets (the normalized state delta, and the normalized reward
        with a reward head) as float32 tensors, from arrays."""
        s, a, s2 = (torch.as_tensor(v, dtype=torch.float32) for v in (states, actions, next_states))
        y = self.delta_norm(s2 - s)
        if "reward" in self.heads:
            y = torch.cat([y, self.reward_norm(torch.as_tensor(rewards, dtype=torch.float32).reshape(-1, 1))], -1)
        return self.inputs(s, a), y

    def forward(self, states: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Raw outputs (K, B, n_out) for (B, S) states and (B, A) actions."""
        return self.net(self.inputs(states, actions))

    def predict(self, states: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Next states (..., S) for states (..., S) and actions (..., A), by the members' mean delta."""
        out = self.net(self.inputs(states.reshape(-1, self.state_size), actions.reshape(-1, self.action_size)))
        delta = out[..., :self.state_size]
        delta = delta[0] if self.members == 1 else delta.mean(0)
        return states + self.delta_norm.inverse(delta).reshape(states.shape)

    @torch.no_grad()
    def disagreement(self, states: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """The members' disagreement on the next state, (B,): the std across members of their mean
        predictions, in units of each entry's typical change (normalized delta), averaged over
        entries. NaN for one member."""
        if self.members == 1:
            return torch.full(states.shape[:1], float("nan"))
        delta = self.net(self.inputs(states, actions))[..., :self.state_size]
        return delta.std(0).mean(-1)

    def step_fn(self, propagation: str = "mean", generator: torch.Generator | None = None):
        """One planning step for N rows: (states (N, S), actions (N, A)) -> (next states (N, S), reward
        (N,) or None, termination (N,) bool or None), the heads' outputs where the model has them.

        propagation:
            "mean": every row goes through all members; their mean predictions are averaged.
            "ts": trajectory sampling TS-inf (PETS): row i always uses member i % K, and a
                probabilistic member's next state is drawn from its Gaussian (the reward head
                gives its mean). N must be a multiple of K.
        """
        k, n_s = self.members, self.state_size
        if propagation not in ("mean", "ts"):
            raise MotorlabError(f"--propagation {propagation!r}: choose mean or ts.")

        @torch.no_grad()
        def step(states: torch.Tensor, actions: torch.Tensor):
            x = self.inputs(states, actions)
            n = x.shape[0]
            if propagation == "mean":
                out = self.net(x)  # (K, N, out)
                mean, _, logit = self.split(out)
                mean = mean.mean(0)
                logit = None if logit is None else logit.mean(0)
            else:
                out = self.net(x.reshape(n // k, k, -1).transpose(0, 1))  # (K, N/K, out): row i -> member i % K
                mean, logvar, logit = self.split(out)
                if logvar is not None:
                    noise = torch.randn(mean[..., :n_s].shape, generator=generator, device=mean.device)
                    mean = torch.cat([mean[..., :n_s] + (0.5 * logvar[..., :n_s]).exp() * noise, mean[..., n_s:]], -1)
                mean = mean.transpose(0, 1).reshape(n, -1)
                logit = None if logit is None else logit.transpose(0, 1).reshape(n)
            next_states = states + self.delta_norm.inverse(mean[..., :n_s])
            reward = self.reward_norm.inverse(mean[..., n_s:n_s + 1])[..., 0] if "reward" in self.heads else None
            return next_states, reward, None if logit is None else logit > 0

        return step

    @torch.no_grad()
    def _planning_layers(self, reward: bool = False) -> tuple[list[torch.Tensor], list[torch.Tensor],
                                                              list[tuple[torch.Tensor, torch.Tensor]]]:
        """Weights, biases and layer-norm affines with the normalizers folded into the first and last
        layers, and tanh_layer_norm's 2x folded into the layers that feed it (silu: no 2x, no affines).
        The last layer keeps the state delta's columns, and with `reward` the reward head's after them (reward_norm folded in as
        delta_norm is); the other heads' columns are left out."""
        net = self.net
        w_in = torch.cat([1 / self.state_norm.std, 1 / self.action_norm.std]).float()[None, :, None]
        shift = torch.cat([self.state_norm.mean, self.action_norm.mean]).float()
        w0 = net.weights[0] * w_in  # (K, in, h): x_norm @ W = x @ (W / std) - (mean / std) @ W
        scaled_shift = shift / torch.cat([self.state_norm.std, self.action_norm.std]).float()
        b0 = net.biases[0] - (scaled_shift @ net.weights[0])[:, None]
        std_d, mean_d = self.delta_norm.std.float(), self.delta_norm.mean.float()
        if reward:
            std_d = torch.cat([std_d, self.reward_norm.std.float()])
            mean_d = torch.cat([mean_d, self.reward_norm.mean.float()])
        cols = len(std_d)
        w_last = net.weights[-1][..., :cols] * std_d  # delta = z * std + mean, folded into the output layer
        b_last = net.biases[-1][..., :cols] * std_d + mean_d
        if net.nonlinearity != "tanh":  # no 2x to fold
            return [w0, *net.weights[1:-1], w_last], [b0, *net.biases[1:-1], b_last], []
        ws = [2 * w0, *(2 * w for w in net.weights[1:-1]), w_last]
        bs = [2 * b0, *(2 * b for b in net.biases[1:-1]), b_last]
        return ws, bs, [(w, b) for w, b in zip(net.ln_weights, net.ln_biases)]

    def _check_reward_head(self, what: str, reward: bool) -> None:
        if reward and "reward" not in self.heads:
            raise MotorlabError(f"{what}(reward=True) needs a model with a reward head (fit with --learn-reward).")

    def fast_predict(self):
        """predict() for planning: the normalizers folded into the first and last layers, the input
        concatenation split into two matmuls, no autograd. ~Half the torch calls per step, which is
        what a small-batch planner pays for (per-call overhead, not FLOPs, dominates on a CPU).
        A probabilistic member predicts its Gaussian's mean; heads are left out."""
        ws, bs, lns = self._planning_layers()
        if self.members == 1:
            first_s, first_a, first_b, rest, norms = self._single_member(ws, bs, lns)

            @torch.no_grad()
            def step(states: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
                return states + _hidden_and_out(torch.addmm(first_b, states, first_s).addmm_(actions, first_a),
                                                rest, norms)
        else:
            @torch.no_grad()
            def step(states: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
                x = torch.cat([states, actions], -1).expand(self.members, -1, -1)
                for i, (w, b) in enumerate(zip(ws, bs)):
                    x = torch.baddbmm(b, x, w)
                    if i < len(ws) - 1:
                        x = _hidden(x, self.nonlinearity)
                        if lns:
                            x = x * lns[i][0] + lns[i][1]
                return states + x.mean(0)
        return step

    def fast_rollout(self, reward: bool = False):
        """Open-loop paths for planning: states (N, S) under action sequences (N, H, A) -> (N, H+1, S),
        the members' mean prediction at each step (as step_fn's "mean" propagation). With `reward` (a
        model with a reward head), (path, rewards (N, H)): the reward head's mean prediction at each
        step comes with the path, from the same pass. The first layer's action part of all H steps is
        one matmul up front (every member's at once), so each step is one matmul per layer; with K
        members the layer norms' affines are folded into the layers after them. A probabilistic member
        predicts its Gaussian's mean (its variance columns, and heads not asked for, are left out)."""
        self._check_reward_head("fast_rollout", reward)
        n_s = self.state_size
        ws, bs, lns = self._planning_layers(reward)
        if self.members == 1:
            first_s, first_a, first_b, rest, norms = self._single_member(ws, bs, lns)

            def first(states, action_part, t):
                return torch.addmm(action_part[:, t], states, first_s)

            def others(x):
                return _hidden_and_out(x, rest, norms)

            def actions_first(actions):
                return torch.matmul(actions, first_a).add_(first_b)  # (N, H, hidden)
        else:
            first_s, first_a, first_b, rest = self._members_folded(ws, bs, lns)
            k = self.members

            def actions_first(actions):  # (K, N, H, hidden)
                n, h, a = actions.shape
                return torch.baddbmm(first_b, actions.reshape(1, n * h, a).expand(k, -1, -1),
                                     first_a).view(k, n, h, -1)

            def first(states, action_part, t):
                return torch.baddbmm(action_part[:, :, t], states.expand(k, -1, -1), first_s)

            def others(x):
                for w, b in rest:
                    x = torch.baddbmm(b, _hidden(x, self.nonlinearity), w)
                return x.mean(0)

        @torch.no_grad()
        def rollout(states: torch.Tensor, actions: torch.Tensor):
            action_part = actions_first(actions)
            path, outs = [states], []
            for t in range(actions.shape[1]):
                out = others(first(path[-1], action_part, t))
                if reward:
                    outs.append(out)
                    out = out[:, :n_s]
                path.append(path[-1] + out)
            path = torch.stack(path, 1)
            return (path, torch.stack(outs, 1)[..., n_s]) if reward else path
        return rollout

    def ts_rollout(self, generator: torch.Generator | None = None, reward: bool = False):
        """Open-loop paths by trajectory sampling (TS-inf, step_fn's "ts" propagation): states (N, S)
        under action sequences (N, H, A) -> (N, H+1, S), row i always on member i % K (N a multiple
        of K), a probabilistic member's next state drawn from its Gaussian; with `reward` (a model
        with a reward head), (path, the head's mean rewards (N, H)).

        Why a path of its own: PETS plans by TS, and step_fn's version spends about a quarter of a
        plan's time on the torch calls around the matmuls (normalizing, concatenating, transposing to
        and from member order at every step ahead). Here the normalizers are folded into the first and
        last layers, the rows stay in member order for the whole horizon, and the first layer's action
        part of all H steps is one matmul: one env's Pusher plan takes ~20% less time. The draws are
        step_fn's (one generator, the same calls in the same order), so a seeded plan is the same on
        either path, to float rounding."""
        self._check_reward_head("ts_rollout", reward)
        k, n_s, g = self.members, self.state_size, self.gaussian
        ws, bs, lns = self._planning_layers(reward)
        cols = ws[-1].shape[-1]  # the delta's columns, and the reward's with `reward`
        if self.probabilistic:  # the state delta's raw log-variances, computed by the same last matmul
            ws[-1] = torch.cat([ws[-1], self.net.weights[-1][..., g:g + n_s]], -1)
            bs[-1] = torch.cat([bs[-1], self.net.biases[-1][..., g:g + n_s]], -1)
            max_lv, min_lv = self.max_logvar[..., :n_s].detach(), self.min_logvar[..., :n_s].detach()
            std_d = self.delta_norm.std.float()  # a draw of the normalized delta, in state units
        first_s, first_a, first_b, rest = self._members_folded(ws, bs, lns)

        @torch.no_grad()
        def rollout(states: torch.Tensor, actions: torch.Tensor):
            n, h, a = actions.shape
            m = n // k
            s = states.reshape(m, k, n_s).transpose(0, 1)  # (K, M, S): member j's rows
            action_part = torch.baddbmm(first_b, actions.reshape(m, k, h * a).transpose(0, 1).reshape(k, m * h, a),
                                        first_a).view(k, m, h, -1)
            path, outs = [s], []
            for t in range(h):
                x = torch.baddbmm(action_part[:, :, t], path[-1], first_s)
                for w, b in rest:
                    x = torch.baddbmm(b, _hidden(x, self.nonlinearity), w)
                delta = x[..., :n_s]
                if self.probabilistic:  # PETS' soft bounds on the log-variance, then a draw (step by step:
                    lv = max_lv - F.softplus(max_lv - x[..., cols:])  # step_fn's numbers, in its order)
                    lv = min_lv + F.softplus(lv - min_lv)
                    noise = torch.randn((k, m, n_s), generator=generator, device=states.device)
                    delta = torch.addcmul(delta, (0.5 * lv).exp_().mul_(std_d), noise)
                if reward:
                    outs.append(x[..., n_s])
                path.append(path[-1] + delta)
            path = torch.stack(path, 2).transpose(0, 1).reshape(n, h + 1, n_s)
            if not reward:
                return path
            return path, torch.stack(outs, 2).transpose(0, 1).reshape(n, h)
        return rollout

    @torch.no_grad()
    def _single_member(self, ws, bs, lns):
        """Member 0's planning layers as 2-d tensors: the first layer split into its state and action rows."""
        n_s = self.state_size
        rest = [(w[0].clone(), b[0, 0].clone()) for w, b in zip(ws[1:], bs[1:])]
        norms = [(w[0, 0].clone(), b[0, 0].clone()) for w, b in lns] if self.nonlinearity == "tanh" else None
        return ws[0][0, :n_s].clone(), ws[0][0, n_s:].clone(), bs[0][0, 0].clone(), rest, norms

    @torch.no_grad()
    def _members_folded(self, ws, bs, lns):
        """All members' planning layers, the first split into its state and action rows, and each layer
        norm's affine (g, beta) folded into the layer after it: (LN(x) g + beta) W + b = LN(x) (g^T W) + (beta W + b)."""
        n_s = self.state_size
        if lns:
            rest = [((g.transpose(1, 2) * w).contiguous(), torch.baddbmm(b, beta, w).contiguous())
                    for (w, b), (g, beta) in zip(zip(ws[1:], bs[1:]), lns)]
        else:  # silu: no layer norm, nothing to fold
            rest = [(w.contiguous(), b.contiguous()) for w, b in zip(ws[1:], bs[1:])]
        return ws[0][:, :n_s].contiguous(), ws[0][:, n_s:].contiguous(), bs[0].contiguous(), rest

    # ---- files -------------------------------------------------------------------

    def save(self, folder: Path, metrics: dict[str, Any] | None = None) -> None:
        """model.safetensors + model.json in `folder`, each written atomically."""
        from safetensors.torch import save

        folder = Path(folder)
        tensors = {k: v.detach().cpu().contiguous() for k, v in self.state_dict().items()}
        atomic_write_bytes(folder / MODEL_WEIGHTS, save(tensors))
        write_json(folder / MODEL_JSON, {
            "format": FORMAT, "architecture": {
                "state_size": self.state_size, "action_size": self.action_size, "hidden": list(self.hidden),
                "members": self.members, "nonlinearity": self.nonlinearity,  # older files: "activation"
                "layer_norm": self.nonlinearity == "tanh",
                "probabilistic": self.probabilistic, "heads": list(self.heads),
                "output": "normalized state delta" + (", reward" if "reward" in self.heads else "")
                          + (" (Gaussian: mean, log-variance)" if self.probabilistic else "")
                          + (", termination logit" if "termination" in self.heads else "")},
            **self.meta, "metrics": metrics or {}})


def _check_weight_shapes(folder: Path, sizes: tuple) -> None:
    """The tensors in model.safetensors have the shapes model.json's architecture implies
    (read from the file's header; the model is built on the meta device, allocating nothing)."""
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(folder / MODEL_WEIGHTS), "pt") as f:
            stored = {k: tuple(f.get_slice(k).get_shape()) for k in f.keys()}
    except FileNotFoundError:
        raise MotorlabError(f"{folder / MODEL_WEIGHTS} is missing; re-run `motorlab dynamics fit`.") from None
    except (SafetensorError, OSError, ValueError) as e:
        raise MotorlabError(f"{folder / MODEL_WEIGHTS} is damaged ({str(e).splitlines()[0]}); "
                            "re-run `motorlab dynamics fit`.") from None
    with torch.device("meta"):
        expected = {k: tuple(v.shape) for k, v in ForwardModel(*sizes[:4], **sizes[4]).state_dict().items()}
    if stored != expected:
        wrong = sorted(k for k in expected.keys() | stored.keys() if stored.get(k) != expected.get(k))
        raise MotorlabError(f"{folder / MODEL_JSON}'s architecture does not match {MODEL_WEIGHTS} "
                            f"({wrong[0]}: {stored.get(wrong[0])} stored, {expected.get(wrong[0])} expected); "
                            "re-run `motorlab dynamics fit`.")


def load_model(path: Path, env_id: str | None = None, state_layout: str | None = None) -> ForwardModel:
    """A forward model from a folder holding model.json + model.safetensors (or from model.json itself).

    Args:
        env_id, state_layout: when given, the model must have been trained for them.

    Raises:
        MotorlabError: missing or corrupt files, or a model for another env or state layout.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    path = Path(path)
    folder = path.parent if path.name in (MODEL_JSON, MODEL_WEIGHTS) else path
    if not (folder / MODEL_JSON).is_file():
        raise MotorlabError(f"{folder / MODEL_JSON} is missing; pass a folder written by `motorlab dynamics fit`.")
    meta = read_json(folder / MODEL_JSON)
    recall_imports(folder)  # a model of a user's env: its module, for the env the model is checked or planned on
    try:
        if meta.get("format") != FORMAT:
            raise KeyError("format")
        arch = meta["architecture"]
        sizes = (int(arch["state_size"]), int(arch["action_size"]), tuple(int(h) for h in arch["hidden"]),
                 int(arch["members"]))
        if min(sizes[0], sizes[1], sizes[3], *sizes[2]) < 1:
            raise ValueError("architecture: sizes must be positive")
        # models written before probabilistic members and heads existed have neither
        # ... and models written before the nonlinearity was a choice are tanh + layer norm (they wrote
        # "activation": "tanh", a name motorlab keeps for muscles)
        options = {"probabilistic": bool(arch.get("probabilistic", False)), "heads": tuple(arch.get("heads", ())),
                   "nonlinearity": arch.get("nonlinearity", "tanh")}
        if not set(options["heads"]) <= set(HEADS):
            raise ValueError(f"architecture: heads {list(options['heads'])}")
        if options["nonlinearity"] not in NONLINEARITIES:
            raise ValueError(f"architecture: nonlinearity {options['nonlinearity']!r}")
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise MotorlabError(f"{folder / MODEL_JSON} is not a motorlab forward model (bad or missing {e}); "
                            "re-run `motorlab dynamics fit`.") from None
    check_meta(meta, sizes[0], str(folder / MODEL_JSON), "re-run `motorlab dynamics fit`.")
    if not isinstance(meta.get("metrics", {}), dict):
        raise MotorlabError(f"{folder / MODEL_JSON}: metrics should be an object; re-run `motorlab dynamics fit`.")
    _check_weight_shapes(folder, (*sizes, options))  # before allocating: a damaged model.json must not ask for terabytes
    model = ForwardModel(*sizes, meta={k: v for k, v in meta.items() if k not in ("format", "architecture", "metrics")},
                         **options)
    try:
        model.load_state_dict(load_file(folder / MODEL_WEIGHTS))
    except FileNotFoundError:
        raise MotorlabError(f"{folder / MODEL_WEIGHTS} is missing; re-run `motorlab dynamics fit`.") from None
    except (SafetensorError, RuntimeError, OSError) as e:
        raise MotorlabError(f"{folder / MODEL_WEIGHTS} does not fit {MODEL_JSON} or is damaged "
                            f"({str(e).splitlines()[0]}); re-run `motorlab dynamics fit`.") from None
    model.metrics = meta.get("metrics", {})
    if env_id is not None and model.meta.get("env_id") != env_id:
        raise MotorlabError(f"{folder} models {model.meta.get('env_id')!r}, not {env_id!r}; "
                            f"fit a model on {env_id} transitions first.")
    if state_layout is not None and model.meta.get("state_layout") != state_layout:
        raise MotorlabError(f"{folder} uses the {model.meta.get('state_layout')!r} state layout, not "
                            f"{state_layout!r}; fit a model with that layout.")
    model.eval()
    return model
