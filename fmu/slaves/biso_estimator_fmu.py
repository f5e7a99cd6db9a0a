"""Slave script of BisoEstimator.fmu (read by pythonfmu); the model is biso_cosim.fmu.estimator."""

import importlib.util

from pythonfmu import Fmi2Slave

if importlib.util.find_spec("biso_cosim") is None:
    # a native host whose PYTHONPATH names a site-packages: read its .pth files (editable installs)
    import site
    import sys

    for _dir in [p for p in sys.path if p.endswith("site-packages")]:
        site.addsitedir(_dir)

from biso_cosim.fmu import _slave, estimator

_slave.hold(globals())  # pythonfmu's loader takes a reference away per instantiation


@_slave.slave_class(estimator.EstimatorSlave)
class BisoEstimator(Fmi2Slave):
    """Attitude estimator of biso_cosim as an FMI 2.0 co-simulation slave."""
