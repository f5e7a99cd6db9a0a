"""FMU export (biso_cosim.fmu)."""
