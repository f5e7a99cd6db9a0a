"""FMI 2.0 co-simulation FMUs of biso_cosim, built with pythonfmu (``biso-cosim fmu build``).

* ``BisoEstimator.fmu``: an attitude estimator (``biso_cosim.estimators``): gyro,
  accelerometer, magnetometer (and speed) in, attitude out (``estimator.py``);
* ``BisoImuPlugin.fmu``: the virtual MPU-9250 and an estimator for another simulator's
  vehicle: true motion in, readings, raw registers, estimate and its error out
  (``imu_plugin.py``);
* ``BisoVehicle.fmu``: the whole co-simulation, as ``biso-cosim run`` (``vehicle.py``).

Their variables come from the package's parameter records (``variables.py``); the slave
machinery, FMI error handling and FMU state are in ``_slave.py``; ``build.py`` builds and
validates; ``host.py`` is a small FMPy master; ``demos/`` connects the FMUs in FMPy, in
libcosim and in a native C master. Guide: docs/fmu.md.

>>> from biso_cosim.fmu import build_fmus, FmuInstance
>>> paths = build_fmus("out/fmu")
>>> with FmuInstance(paths[0], start_values={"estimator": "biso_plus"}) as fmu:
...     fmu.set({"accel_s.z": 9.81, "mag_s.y": 20.0, "mag_s.z": -40.0})
...     fmu.step(0.005)
...     fmu.get(["estimate.heading"])
"""

from biso_cosim.fmu.build import FMU_NAMES, build_fmu, build_fmus, validate_fmu
from biso_cosim.fmu.host import FmuInstance
from biso_cosim.fmu.variables import variable_table, variables_of

__all__ = ["FMU_NAMES", "build_fmu", "build_fmus", "validate_fmu", "FmuInstance", "variables_of", "variable_table"]
