"""FMI co-simulation FMUs of biso_cosim (``biso-cosim fmu build``).

* ``BisoEstimator-fmi2.fmu`` / ``-fmi3.fmu`` (native C, no Python): an attitude estimator
  (``biso_cosim.estimators``): gyro, accelerometer, magnetometer (and speed) in, attitude out;
* ``BisoImuPlugin-fmi2.fmu`` / ``-fmi3.fmu`` (native C, no Python): the virtual MPU-9250 and
  an estimator for another simulator's vehicle: true motion in, readings, raw registers,
  estimate and its error out;
* ``BisoVehicle-fmi2.fmu`` / ``-fmi3.fmu`` (Python-based: it runs MuJoCo): the whole
  co-simulation, as ``biso-cosim run`` (``vehicle.py``); its binary is our C shell that embeds
  CPython (``native/src/python``, ``native/python_shell.py``) and calls the slave through
  ``_embedded.py``.

Their variables come from the package's parameter records (``variables.py``); the native
FMUs' C sources, generated data and build are in ``native/``; the Python slave machinery in
``_slave.py``; ``build.py`` builds and validates; ``host.py`` is a small FMPy master;
``demos/`` connects the FMUs in FMPy, in libcosim and in a native C master. Guide: docs/fmu.md.

>>> from biso_cosim.fmu import build_fmus, FmuInstance
>>> paths = build_fmus("out/fmu", only=["BisoEstimator"])
>>> with FmuInstance(paths[1], start_values={"estimator": "biso_plus"}) as fmu:   # FMI 3.0
...     fmu.set({"accel_s.z": 9.81, "mag_s.y": 20.0, "mag_s.z": -40.0})
...     fmu.step(0.005)
...     fmu.get(["estimate.heading"])
"""

from biso_cosim.fmu.build import FMU_NAMES, build_fmu, build_fmus, validate_fmu
from biso_cosim.fmu.host import FmuCallError, FmuInstance
from biso_cosim.fmu.variables import variable_table, variables_of

__all__ = ["FMU_NAMES", "build_fmu", "build_fmus", "validate_fmu", "FmuInstance", "FmuCallError", "variables_of",
           "variable_table"]
