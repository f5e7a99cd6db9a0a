"""``BisoImuPlugin.fmu``: the virtual MPU-9250 and an estimator for someone else's vehicle.

The host gives the true motion at every communication point (angular rate, specific force,
attitude; optionally position, velocity, temperature). The plugin computes the Earth field
in body axes (WMM at the site and date), runs ``biso_cosim.sensors.MPU9250`` on the truth,
feeds every output sample to the estimator, and outputs the latest sample (SI readings, raw
registers, flags), the estimate after it, and its error against the input truth at the
sample's time stamp.

Timing: the truth given at communication point t_k is the sensor's input sample k, so the
truth rate is 1/h for a step size h; the first step fixes h (it must make the truth rate an
integer multiple or fraction of the chip's internal rate: 1 ms, 0.5 ms, 2 ms, 5 ms, 20 ms ...
for the default registers) and later steps must keep it. Between communication points the
chip interpolates the truth linearly. The outputs after the step from t_k are the samples
the chip latched at t ≤ t_k (``new_samples`` of them, 0 when none: outputs held). For the
same truth rows and seed the readings equal ``MPU9250.simulate`` on the whole array, bit for
bit, and the estimates equal the estimator run on those readings.
"""

from __future__ import annotations

import datetime
from typing import Any

import numpy as np

from biso_cosim.fmu._slave import BisoSlave, FmuConfigError

__all__ = ["ImuPluginSlave"]

_TRUTH_HEADS = ("omega", "force", "q", "pos", "vel")


def _nlerp(q0: np.ndarray, q1: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Attitudes between q0 and q1 on the shorter arc (normalised linear interpolation)."""
    q1 = q1 if float(np.dot(q0, q1)) >= 0.0 else -q1
    q = (1.0 - frac)[:, None] * q0 + frac[:, None] * q1
    return q / np.linalg.norm(q, axis=1, keepdims=True)


class ImuPluginSlave(BisoSlave):
    """Virtual MPU-9250 (with AK8963) and attitude estimator driven by the host's vehicle truth."""

    fmu = "BisoImuPlugin"
    summary = ("Virtual MPU-9250 + AK8963 and attitude estimator of biso_cosim for another simulator's "
               "vehicle: true motion in; readings, raw registers, estimate and its error out")
    default_step_s = 0.001
    default_stop_s = 10.0
    fmi_options = {**BisoSlave.fmi_options, "canHandleVariableCommunicationStepSize": False,
                   "canGetAndSetFMUstate": True, "canSerializeFMUstate": True}

    def _configure(self) -> None:
        from biso_cosim.sensors import EarthField, MagneticEnvironment

        values = self.values
        try:
            date = datetime.date.fromisoformat(values["site.date"])
        except ValueError:
            raise ValueError(f"site.date must be an ISO date YYYY-MM-DD, got {values['site.date']!r}") from None
        self.earth = EarthField(values["site.lat_deg"], values["site.lon_deg"], values["site.alt_m"], date)
        self.magnetic = MagneticEnvironment(self.earth)
        self.registers = {v.key[1]: values[v.name] for v in self.specs
                          if v.key[0] == "register" and v.name in self.set_by_host} or None
        self.mounting = self.mounting_quaternion()
        self.imu = self._make_imu(1000.0)  # checks profile, seed, registers; the first step sets the rate
        self.name, params = self.estimator_choice(site_declination=self.earth.declination_rad)
        self.est = self.make_estimator(self.imu.output_rate_hz, params)
        self.use_speed = values["use_velocity"]
        if self.use_speed and "speed_mps" not in self.est.inputs:
            raise ValueError(f"use_velocity: estimator {self.name!r} takes no speed input (only biso_plus does)")
        self.use_temperature = values["use_temperature"]
        self.step_size: float | None = None
        self.prev_row: np.ndarray | None = None

    def _make_imu(self, input_rate_hz: float):
        from biso_cosim.sensors import MPU9250

        seed = self.values["sensor.seed"]
        if seed < 0:
            raise ValueError(f"sensor.seed must be >= 0, got {seed}")
        return MPU9250(self.values["sensor.profile"], seed=seed, registers=self.registers,
                       mounting=self.mounting, input_rate_hz=input_rate_hz)

    def _advance(self, step_size: float) -> None:
        if self.step_size is None:
            try:
                imu = self._make_imu(1.0 / step_size)
            except ValueError as exc:
                raise FmuConfigError(f"the step size sets the truth rate 1/h = {1.0 / step_size:g} Hz: {exc}") from None
            if imu.output_rate_hz != self.imu.output_rate_hz:  # cannot happen: the registers set it
                raise FmuConfigError("output rate changed with the input rate")
            self.imu, self.step_size = imu, step_size
        elif abs(step_size - self.step_size) > 1e-9 * self.step_size:
            raise FmuConfigError(f"the step size must stay {self.step_size!r} s (the first step set the truth "
                                 f"rate of the sensor), got {step_size!r}")
        omega, force, q, pos, vel = (np.array(self.vector(h)) for h in _TRUTH_HEADS)
        norm = float(np.linalg.norm(q))
        if norm < 1e-6:
            raise FmuConfigError(f"q_wb must be a non-zero quaternion, got {q.tolist()}")
        q = q / norm
        mag_b = self.magnetic.field_b(q[None, :], pos[None, :])
        temperature = self.values["temperature"] if self.use_temperature else None
        t_in = self.imu.time_s
        samples = self.imu.simulate(omega[None, :], force[None, :], mag_b, temperature)
        row = np.concatenate(([t_in], q, vel))
        prev = self.prev_row if self.prev_row is not None else row  # the chip starts settled
        self.prev_row = row
        self.put_readings(samples, self.start_time)
        if len(samples.t_s) == 0:
            return
        frac = np.clip((samples.t_s - t_in) / step_size + 1.0, 0.0, 1.0)
        q_true = _nlerp(prev[1:5], q, frac)
        extra: dict[str, Any] = {}
        if self.use_speed:
            from biso_cosim.frames import quat_conjugate, quat_rotate

            v_w = (1.0 - frac)[:, None] * prev[5:8] + frac[:, None] * vel
            extra["speed_mps"] = quat_rotate(quat_conjugate(q_true), v_w)[:, 0]
        out = self.est.update(samples.gyro_b, samples.accel_b, samples.mag_b, **extra)
        bias = None if out.gyro_bias_b is None else out.gyro_bias_b[-1]
        self.put_estimate(out.q_wb[-1], out.flags[-1], bias)
        self.put_errors(out.q_wb[-1], q_true[-1])

    def model_state(self) -> Any:
        return {"imu": self.imu.get_state(), "estimator": self.est.get_state(), "step_size": self.step_size,
                "prev_row": self.prev_row}

    def restore_model_state(self, state: Any) -> None:
        if state["step_size"] != self.step_size:
            self.imu = self._make_imu(1000.0 if state["step_size"] is None else 1.0 / state["step_size"])
            self.step_size = state["step_size"]
        self.imu.set_state(state["imu"])
        self.est.set_state(state["estimator"])
        self.prev_row = state["prev_row"]
