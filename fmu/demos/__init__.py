"""Demonstrations of the FMUs: an FMPy master (``master``), a native C master (``native``),
and the Open Simulation Platform's libcosim (``libcosim``)."""
