"""Gymnasium environments (biso_cosim.envs)."""
