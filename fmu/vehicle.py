"""``BisoVehicle`` (``-fmi2.fmu``, ``-fmi3.fmu``): the whole co-simulation
(``biso_cosim.cosim.CoSimulation``) as a slave.

The MuJoCo car drives a route (the scripted driver, or the inputs ``steer``, ``drive``,
``brake`` with ``external_driver``); the virtual MPU-9250 and one estimator run in the loop,
exactly as ``biso-cosim run`` runs them: each communication step is a whole number of
control periods (20 ms by default), each period is one ``CoSimulation.step``. The outputs
are the latest sensor sample of the step, the truth interpolated to its time stamp (what
the run's log holds), the estimate after it and its error.

FMU state: get/set FMU state and serialisation take the whole co-simulation
(``CoSimulation.get_state``: MuJoCo, driver, sensor, estimator, counters), so a master can
go back in time and repeat a step with other inputs bit for bit.

The slave uses CoSimulation's public API only; the C shell that embeds Python and calls it
is ``native/src/python`` (``_embedded.py`` is its Python side).
"""

from __future__ import annotations

from biso_cosim.fmu._slave import BisoSlave

__all__ = ["VehicleSlave"]

# output key head → attribute of biso_cosim.vehicle.sim.Truth
_TRUTH_OUTPUTS = (("truth_omega", "omega_b"), ("truth_force", "specific_force_b"), ("truth_q", "q_wb"),
                  ("truth_pos", "pos_w"), ("truth_vel", "vel_w"), ("truth_speed", "speed_mps"))


class VehicleSlave(BisoSlave):
    """MuJoCo car on a route with the virtual MPU-9250 and an estimator in the loop."""

    fmu = "BisoVehicle"

    def _configure(self) -> None:
        from biso_cosim.cosim import CoSimulation, EstimatorSpec
        from biso_cosim.estimators import estimator_vehicle_params

        values = self.values
        self.name, params = self.estimator_choice()  # an unset declination: the route site's (CoSimulation)
        # the parameters the estimator takes from its vehicle (Estimator.vehicle_params: the rear axle's
        # position, its slip angle per g, its tyres' linear range): the car's (CoSimulation), unless the host set them
        for name in estimator_vehicle_params(self.name):
            if not any(v.key[:3] == ("param", self.name, name) and v.name in self.set_by_host for v in self.specs):
                params.pop(name, None)
        # stepping goes on past CoSimulation's duration (which only ends run()), so the
        # duration is the route's default
        registers = {v.key[1]: values[v.name] for v in self.specs
                     if v.key[0] == "register" and v.name in self.set_by_host} or None
        self.sim = CoSimulation(
            values["route"], seed=values["sensor.seed"],
            estimators=[EstimatorSpec(self.name, params)], sensor_profile=values["sensor.profile"],
            registers=registers, mounting=self.mounting_quaternion(),
            gyro_calibration_s=values["sensor.gyro_calibration_s"],
            physics_rate_hz=values["physics_rate_hz"], control_rate_hz=values["control_rate_hz"], keep_log=False)
        self.est = self.sim.estimators[self.name]
        self.external = values["external_driver"]

    def _advance(self, step_size: float) -> None:
        from biso_cosim.vehicle.driver import DriverCommand

        n = self.samples_in(step_size, self.sim.vehicle.control_rate_hz, "control (control_rate_hz)")
        # the setters keep drive in [-1, 1] and brake in [0, 1] (the inputs' min and max)
        command = DriverCommand(*self.vector("command")) if self.external else None
        latest, count = None, 0
        for _ in range(n):
            samples, truth, outputs = self.sim.step(command)
            if len(samples.t_s):
                latest, count = (samples, truth, outputs[self.name]), count + len(samples.t_s)
        self.put("cross_track", self.sim.vehicle.driver.state.cross_track_m)
        self.put("finished", self.sim.vehicle.driver.finished)
        if latest is None:
            self.put("new_samples", 0)
            return
        samples, truth, estimate = latest
        self.put_readings(samples, self.start_time, count)
        for head, name in _TRUTH_OUTPUTS:
            self.put(head, getattr(truth, name)[-1])
        self.put_estimate(estimate.q_wb[-1], estimate.flags[-1],
                          None if estimate.gyro_bias_b is None else estimate.gyro_bias_b[-1])
        self.put_errors(estimate.q_wb[-1], truth.q_wb[-1])

    def apply_estimator_params(self, changes) -> None:
        self.est.set_params(**changes)

    def release_model(self) -> None:
        self.sim = None
        self.est = None

    def model_state(self):
        return self.sim.get_state()

    def restore_model_state(self, state) -> None:
        self.sim.set_state(state)
