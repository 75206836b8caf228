"""The simulated arm (MuJoCo) and the nominal model the controller believes in."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from host_sim.uncertainty import Uncertainty, UncertaintyConfig, perturb_model

REPO = Path(__file__).resolve().parent.parent
DEFAULT_MJCF = REPO / "host_sim" / "models" / "ur5e_arm.xml"


class Arm:
    def __init__(self, mjcf: Path = DEFAULT_MJCF, keyframe: str = "home",
                 uncertainty: UncertaintyConfig | None = None) -> None:
        self.model = mujoco.MjModel.from_xml_path(str(mjcf))
        ucfg = uncertainty or UncertaintyConfig()
        self.uncertainty = Uncertainty(ucfg, self.model.nu)
        perturb_model(self.model, ucfg, self.uncertainty.rng)
        self.parametric = bool(ucfg.mass_error or ucfg.inertia_error or ucfg.com_error_m)
        self.data = mujoco.MjData(self.model)
        self._mass = np.zeros((self.model.nv, self.model.nv))
        # The nominal model: what the firmware's header was generated from. Uncertainty makes
        # self.model differ from it; w is measured against it.
        self.nominal = mujoco.MjModel.from_xml_path(str(mjcf))
        self.nominal_data = mujoco.MjData(self.nominal)
        key = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_KEY, keyframe)
        if key < 0:
            raise ValueError(f"{mjcf}: no keyframe '{keyframe}'")
        mujoco.mj_resetDataKeyframe(self.model, self.data, key)
        mujoco.mj_forward(self.model, self.data)
        self.n = self.model.nu
        self.torque_limit = self.model.actuator_ctrlrange[:, 1].copy()
        self.period = float(self.model.opt.timestep)
        self.step_count = 0

    @property
    def q(self) -> np.ndarray:
        return self.data.qpos.copy()

    @property
    def qd(self) -> np.ndarray:
        return self.data.qvel.copy()

    def step(self, tau: np.ndarray, tau_commanded: np.ndarray | None = None) -> np.ndarray:
        """Advance one period under tau; returns w, the total uncertainty over this period.

        w = (acceleration the nominal model predicts for the commanded torque) - (true
        acceleration), which is exactly the w of e_ddot = u + w under inverse dynamics control.
        tau_commanded differs from tau when the bus delays a new command into the period (bus
        timing emulation): the torque that did not act is then part of w, as the controller sees it.
        """
        self.data.ctrl[:] = tau
        nd = self.nominal_data
        nd.qpos[:] = self.data.qpos
        nd.qvel[:] = self.data.qvel
        nd.ctrl[:] = tau if tau_commanded is None else tau_commanded
        mujoco.mj_forward(self.nominal, nd)
        u = self.uncertainty
        if u.time_varying:
            # M and V of the true arm at the step's start. Without parametric error the true arm's
            # are the nominal one's, just computed: no second forward pass.
            src_model, src_data = self.nominal, nd
            if self.parametric:
                mujoco.mj_forward(self.model, self.data)
                src_model, src_data = self.model, self.data
            mujoco.mj_fullM(src_model, src_data, self._mass)
            self.data.qfrc_applied[:] = u.extra_force(self.step_count * self.period, self._mass,
                                                      src_data.qfrc_bias, tau, self.data.qvel)
        else:
            self.data.qfrc_applied[:] = u.extra_force(0.0, self._mass, self.data.qfrc_bias, tau, self.data.qvel)
        mujoco.mj_step(self.model, self.data)  # qacc is the acceleration at the step's start
        self.step_count += 1
        return nd.qacc - self.data.qacc
