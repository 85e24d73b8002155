"""A planar two-link arm (Reacher's) simulated in batches, step for step as MuJoCo does.

Why not MuJoCo itself: for a 2-DOF model almost all of a MuJoCo step is the generic
pipeline's per-call bookkeeping (~1.4 µs per forward pass, eight per Reacher action), so
`mujoco.rollout` tops out near 90k transitions/s per core. The arm's equations of motion
fit in a few lines and run as NumPy array operations over thousands of episodes at once,
~20x faster per core. Every operation follows the order MuJoCo's C code uses (RK4's stage
sums, the LDL solve, the soft joint-limit constraint), so the states agree with MuJoCo's to
rounding wherever MuJoCo's constraint solver converges (it stops at its tolerance; see
reacher_sim for what that leaves). `PlanarArm.from_model` takes its constants from the compiled MjModel and checks
the closed form against `mj_forward` at random states, limits included; any model it does
not reproduce gets `None`, and the caller simulates it with `mujoco.rollout` instead.

Equations of motion (hinges about parallel axes; q1 is the elbow angle):
    M(q) = [[m00 + 2 b cos q1, m01 + b cos q1], [m01 + b cos q1, m11]]   (armature included)
    bias = [-b sin q1 (2 v0 v1 + v1^2), b sin q1 v0^2]                      (Coriolis, centrifugal)
    M qacc = gear * clip(ctrl) - damping * v - bias + J' f                  (f: joint-limit force)
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

_MINVAL = 1e-15  # MuJoCo's mjMINVAL, mjMINIMP, mjMAXIMP
_MINIMP, _MAXIMP = 0.0001, 0.9999
_RK4_B = (1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0)
CHECK_TOLERANCE = 1e-9  # relative agreement with mj_forward's qacc that `from_model` demands


@dataclass(frozen=True)
class JointLimit:
    """MuJoCo's soft limit of one joint (range, solref, solimp, margin), as `mj_makeImpedance` uses it."""

    dof: int
    low: float
    high: float
    margin: float
    solimp: tuple[float, float, float, float, float]
    stiffness: float  # K of the reference acceleration aref = -B vel - K imp (pos - margin)
    damping: float  # B
    invweight0: float  # MuJoCo's diagonal approximation of the constraint's A (dof_invweight0)

    def impedance(self, pos: np.ndarray) -> np.ndarray:
        """MuJoCo's getimpedance for violations `pos` (all below the margin), clamped as mj_makeImpedance does."""
        d0, dwidth, width, mid, power = self.solimp
        if d0 == dwidth or width <= _MINVAL:
            imp = np.full_like(pos, 0.5 * (d0 + dwidth))
        else:
            x = np.abs((pos - self.margin) / width)
            if power == 1:
                y = x
            else:
                a = 1 / mid ** (power - 1)
                b = 1 / (1 - mid) ** (power - 1)
                y = np.where(x <= mid, a * x ** power, 1 - b * (1 - x) ** power)
            imp = np.where(x >= 1, dwidth, np.where(x <= 0, d0, d0 + y * (dwidth - d0)))
        return np.clip(imp, _MINIMP, _MAXIMP)


@dataclass(frozen=True)
class PlanarArm:
    """Constants of the arm's equations of motion (see the module docstring)."""

    m00: float
    m01: float
    m11: float
    b: float
    damping: tuple[float, float]
    gear: tuple[float, float]
    ctrl_low: tuple[float, float]
    ctrl_high: tuple[float, float]
    timestep: float
    limit: JointLimit | None

    @classmethod
    def from_model(cls, model: mujoco.MjModel, checks: int = 256, seed: int = 0) -> PlanarArm | None:
        """The arm of `model` (two hinges, two motors, RK4), or None where the closed form does not
        reproduce MuJoCo's forward dynamics to CHECK_TOLERANCE (then simulate it in MuJoCo)."""
        if not _is_planar_pair(model):
            return None
        data = mujoco.MjData(model)
        mass = np.zeros((2, 2))

        def full_m(elbow: float) -> np.ndarray:
            data.qpos[:] = (0.0, elbow)
            mujoco.mj_forward(model, data)
            mujoco.mj_fullM(model, data, mass)
            return mass.copy()

        straight, bent = full_m(0.0), full_m(np.pi / 2)  # cos(pi/2) ~ 6e-17: the constant terms
        limit = None
        limited = np.flatnonzero(model.jnt_limited)
        if len(limited) == 1:
            j = int(limited[0])
            solref, solimp = model.jnt_solref[j], model.jnt_solimp[j]
            timeconst, dampratio = float(solref[0]), float(solref[1])
            dmax = float(solimp[1])
            if not model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_REFSAFE:
                timeconst = max(timeconst, 2 * model.opt.timestep)
            limit = JointLimit(dof=j, low=float(model.jnt_range[j, 0]), high=float(model.jnt_range[j, 1]),
                               margin=float(model.jnt_margin[j]), solimp=tuple(float(x) for x in solimp),
                               stiffness=1 / (dmax * dmax * timeconst * timeconst * dampratio * dampratio),
                               damping=2 / (dmax * timeconst), invweight0=float(model.dof_invweight0[j]))
        gear = model.actuator_gear[:, 0]
        arm = cls(m00=float(bent[0, 0]), m01=float(bent[0, 1]), m11=float(straight[1, 1]),
                  b=float(straight[0, 1] - bent[0, 1]), damping=tuple(model.dof_damping.astype(float)),
                  gear=tuple(gear.astype(float)), ctrl_low=tuple(model.actuator_ctrlrange[:, 0].astype(float)),
                  ctrl_high=tuple(model.actuator_ctrlrange[:, 1].astype(float)), timestep=float(model.opt.timestep),
                  limit=limit)
        return arm if arm._agrees_with(model, checks, seed) else None

    def _agrees_with(self, model: mujoco.MjModel, n: int, seed: int) -> bool:
        """qacc of the closed form vs mj_forward at n random states, a third of them past a limit."""
        rng = np.random.default_rng(seed)
        q = rng.uniform(-np.pi, np.pi, size=(n, 2))
        if self.limit is not None:  # press on the limit: inside the impedance's width and far beyond it
            past = rng.uniform(0, 0.05, size=n // 3) * rng.choice([1e-2, 1.0], size=n // 3)
            q[: n // 3, self.limit.dof] = np.where(rng.random(n // 3) < 0.5, self.limit.low - past,
                                                   self.limit.high + past)
        v = rng.normal(0, 20, size=(n, 2))
        u = rng.uniform(-1.5, 1.5, size=(n, 2))
        data = mujoco.MjData(model)
        want = np.empty((n, 2))
        for i in range(n):
            data.qpos[:], data.qvel[:], data.ctrl[:] = q[i], v[i], u[i]
            mujoco.mj_forward(model, data)
            want[i] = data.qacc
        got = np.stack(self.qacc(q[:, 0], q[:, 1], v[:, 0], v[:, 1], *self.actuator_torque(u)), axis=1)
        return bool(np.all(np.abs(got - want) <= CHECK_TOLERANCE * (1 + np.abs(want))))

    def actuator_torque(self, ctrl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """qfrc_actuator of controls (..., 2): the motors' gear times the control clamped to its range."""
        return tuple(self.gear[i] * np.clip(ctrl[..., i], self.ctrl_low[i], self.ctrl_high[i]) for i in (0, 1))

    def qacc(self, q0, q1, v0, v1, tau0, tau1) -> tuple[np.ndarray, np.ndarray]:
        """Joint accelerations for batches of joint angles q, velocities v and actuator torques tau."""
        c, s = np.cos(q1), np.sin(q1)
        bs = self.b * s
        # qfrc_smooth = qfrc_passive - qfrc_bias + qfrc_actuator, as mj_fwdAcceleration sums it
        f0 = (-self.damping[0] * v0 + bs * v1 * (2 * v0 + v1)) + tau0
        f1 = (-self.damping[1] * v1 - bs * v0 * v0) + tau1
        # M = L' D L with L unit lower triangular, factored from the last dof up as mj_factorM does
        m01 = self.m01 + self.b * c
        inv_d1 = 1 / self.m11
        l10 = m01 * inv_d1
        d0 = (self.m00 + 2 * self.b * c) - l10 * m01
        a0 = (f0 - l10 * f1) / d0
        a1 = f1 * inv_d1 - l10 * a0
        if self.limit is not None:
            self._limit_force(self.limit, (q0, q1), (v0, v1), (a0, a1), l10, d0, inv_d1)
        return a0, a1

    @staticmethod
    def _limit_force(lim: JointLimit, q, v, a, l10, d0, inv_d1) -> None:
        """Adds the joint-limit force to the accelerations `a` in place where the joint is past its
        limit: the one-constraint minimum of MuJoCo's (Newton) solver, f = max(0, -(J a - aref)/(A + R))."""
        k = lim.dof
        lo, hi = q[k] - lim.low, lim.high - q[k]
        rows = np.flatnonzero((lo < lim.margin) | (hi < lim.margin))
        if len(rows) == 0:
            return
        below = lo[rows] < lim.margin
        jac = np.where(below, 1.0, -1.0)
        pos = np.where(below, lo[rows], hi[rows])
        imp = lim.impedance(pos)
        r = np.maximum(_MINVAL, (1 - imp) * lim.invweight0 / imp)
        aref = -lim.damping * (jac * v[k][rows]) - lim.stiffness * imp * (pos - lim.margin)
        # column k of M^-1 from the factors: M^-1 = L^-1 D^-1 L^-T
        minv_00 = 1 / d0[rows]
        minv_10 = -l10[rows] * minv_00
        col = (minv_00, minv_10) if k == 0 else (minv_10, inv_d1 + l10[rows] * l10[rows] * minv_00)
        force = np.maximum(0.0, -(jac * a[k][rows] - aref) / (col[k] + r))
        a[0][rows] += col[0] * jac * force
        a[1][rows] += col[1] * jac * force

    def rollout(self, qpos: np.ndarray, qvel: np.ndarray, controls: np.ndarray, frame_skip: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """E episodes of T actions, each held for `frame_skip` RK4 substeps as MuJoCo's mj_step takes them.

        Args:
            qpos, qvel: initial joint angles and velocities, (E, 2).
            controls: (E, T, 2).

        Returns:
            qpos (E, T+1, 2) and qvel (E, T+1, 2) after every action, and the joint angles of RK4's
            last stage in each action's last substep (E, T, 2): where MuJoCo leaves the kinematics
            (`data.xpos`) after `mj_step`.
        """
        n, steps = controls.shape[:2]
        h = self.timestep
        qs, vs = np.empty((n, steps + 1, 2)), np.empty((n, steps + 1, 2))
        stage = np.empty((n, steps, 2))
        qs[:, 0], vs[:, 0] = qpos, qvel
        q0, q1 = qpos[:, 0].copy(), qpos[:, 1].copy()
        v0, v1 = qvel[:, 0].copy(), qvel[:, 1].copy()
        b0, b1, b2, b3 = _RK4_B
        for t in range(steps):
            u0, u1 = self.actuator_torque(controls[:, t])
            for _ in range(frame_skip):
                # mj_RungeKutta: X_i = X_0 + h * sum_j A_ij F_j, A = [[1/2], [0, 1/2], [0, 0, 1]]
                a0, a1 = self.qacc(q0, q1, v0, v1, u0, u1)
                s1 = (q0 + h * (0.5 * v0), q1 + h * (0.5 * v1), v0 + (0.5 * a0) * h, v1 + (0.5 * a1) * h)
                c0, c1 = self.qacc(*s1, u0, u1)
                s2 = (q0 + h * (0.5 * s1[2]), q1 + h * (0.5 * s1[3]), v0 + (0.5 * c0) * h, v1 + (0.5 * c1) * h)
                d0, d1 = self.qacc(*s2, u0, u1)
                s3 = (q0 + h * s2[2], q1 + h * s2[3], v0 + d0 * h, v1 + d1 * h)
                e0, e1 = self.qacc(*s3, u0, u1)
                # dX = sum_i B_i F_i, summed in MuJoCo's order; then v += h dXa, q += h dXv
                dq0 = ((v0 * b0 + s1[2] * b1) + s2[2] * b2) + s3[2] * b3
                dq1 = ((v1 * b0 + s1[3] * b1) + s2[3] * b2) + s3[3] * b3
                dv0 = ((a0 * b0 + c0 * b1) + d0 * b2) + e0 * b3
                dv1 = ((a1 * b0 + c1 * b1) + d1 * b2) + e1 * b3
                q0, q1 = q0 + h * dq0, q1 + h * dq1
                v0, v1 = v0 + dv0 * h, v1 + dv1 * h
            stage[:, t, 0], stage[:, t, 1] = s3[0], s3[1]
            qs[:, t + 1, 0], qs[:, t + 1, 1] = q0, q1
            vs[:, t + 1, 0], vs[:, t + 1, 1] = v0, v1
        return qs, vs, stage


def _is_planar_pair(model: mujoco.MjModel) -> bool:
    """Two hinges in a chain, two plain motors on them, RK4, at most one joint limit (one soft
    constraint, whose solution is closed-form), nothing else acting."""
    if model.nq != 2 or model.nv != 2 or model.nu != 2 or model.na != 0 or model.neq or model.ntendon:
        return False
    hinge = mujoco.mjtJoint.mjJNT_HINGE
    if not (np.all(model.jnt_type == hinge) and model.dof_parentid[1] == 0 and model.dof_parentid[0] == -1):
        return False
    if model.opt.integrator != mujoco.mjtIntegrator.mjINT_RK4 or np.any(model.jnt_stiffness) \
            or np.any(model.dof_frictionloss) or np.count_nonzero(model.jnt_limited) > 1:
        return False
    motors = (np.all(model.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT)
              and list(model.actuator_trnid[:, 0]) == [0, 1]
              and np.all(model.actuator_dyntype == mujoco.mjtDyn.mjDYN_NONE)
              and np.all(model.actuator_gaintype == mujoco.mjtGain.mjGAIN_FIXED)
              and np.all(model.actuator_biastype == mujoco.mjtBias.mjBIAS_NONE)
              and np.all(model.actuator_gainprm[:, 0] == 1) and np.all(model.actuator_ctrllimited)
              and not np.any(model.actuator_forcelimited) and np.all(model.actuator_gear[:, 1:] == 0))
    # contacts must be off or impossible; the caller hands in the arm without world geoms
    return bool(motors) and (model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT or model.ngeom == 0
                             or not (model.geom_contype[:, None] & model.geom_conaffinity[None, :]).any())
