"""``BisoEstimator.fmu``: one attitude estimator of ``biso_cosim.estimators`` as an FMI slave.

Inputs gyro, accelerometer and magnetometer (SI, sensor axes), optionally the speed for
``biso_plus``; outputs the attitude after the latest sample. Timing: one communication step
of n/``fs_hz`` seconds feeds the inputs set at its start to the estimator n times (sample
and hold), so with steps of 1/``fs_hz`` the output after step i is the estimate of sample i,
exactly what ``estimate_attitude`` returns for row i (the estimators' streaming is bit for
bit equal to their batch). Estimator parameters are tunable: a change between steps acts
through ``set_params`` (no jump in the attitude).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from biso_cosim.fmu._slave import BisoSlave

__all__ = ["EstimatorSlave"]


class EstimatorSlave(BisoSlave):
    """Attitude estimator (BISO, its baselines, biso_plus) of the biso_cosim package."""

    fmu = "BisoEstimator"
    summary = ("Attitude estimator of biso_cosim (BISO: Aleshkin et al. 2024, baselines, biso_plus): "
               "gyro, accelerometer, magnetometer in, attitude q_wb out")
    default_step_s = 0.005
    default_stop_s = 10.0
    fmi_options = {**BisoSlave.fmi_options, "canHandleVariableCommunicationStepSize": True,
                   "canGetAndSetFMUstate": True, "canSerializeFMUstate": True}

    def _configure(self) -> None:
        from biso_cosim.frames import quat_to_matrix

        self.name, params = self.estimator_choice()
        self.est = self.make_estimator(self.values["fs_hz"], params)
        q_bs = self.mounting_quaternion()
        self.r_bs = None if q_bs is None else quat_to_matrix(q_bs)
        self.use_speed = self.values["use_speed"]
        if self.use_speed and "speed_mps" not in self.est.inputs:
            raise ValueError(f"use_speed: estimator {self.name!r} takes no speed input (only biso_plus does)")

    def _advance(self, step_size: float) -> None:
        n = self.samples_in(step_size, self.est.fs_hz, "sample (fs_hz)")
        rows = np.array([self.vector("gyro"), self.vector("accel"), self.vector("mag")])
        if self.r_bs is not None:
            rows = rows @ self.r_bs.T
        gyro, accel, mag = (np.repeat(r[None, :], n, axis=0) for r in rows)
        extra = {"speed_mps": np.full(n, self.values["speed"])} if self.use_speed else {}
        out = self.est.update(gyro, accel, mag, **extra)
        bias = None if out.gyro_bias_b is None else out.gyro_bias_b[-1]
        self.put_estimate(out.q_wb[-1], out.flags[-1], bias)

    def model_state(self) -> Any:
        return {"estimator": self.est.get_state(), "params": self.est.params}

    def restore_model_state(self, state: Any) -> None:
        params = state["params"]
        self.est.set_params(**{f.name: getattr(params, f.name) for f in dataclasses.fields(params)})
        self.est.set_state(state["estimator"])
