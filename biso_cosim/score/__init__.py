"""Scoring attitude estimators on real recordings with a reference (``biso-cosim score``).

>>> from biso_cosim.score import score
>>> result = score("data_hdf5", ["biso_plus", "vqf"], out="out/score")
>>> result["groups"]["all_trials"]["methods"]["vqf"]["total_rmse_deg"]

Recordings (``readers``): BROAD's HDF5 trials, NumPy ``.npz`` files with BROAD's keys, and
run logs (``log.csv`` of ``biso-cosim run``, or any CSV with the sensor columns and a
reference ``true_q*``). Methods (``methods``): our estimators by name with parameters, VQF
and imufusion, a user's own estimator. Errors (``metrics``): BROAD's total, heading and
inclination RMSE over the movement samples, per trial and per group (Laidig et al. 2021).
See docs/score.md.
"""

from biso_cosim.score.methods import Method, make_method, method_names
from biso_cosim.score.metrics import ERRORS, broad_errors_rad, error_quat_earth, rmse_deg, trial_rmse_deg
from biso_cosim.score.readers import Recording, find_recordings, read_recording
from biso_cosim.score.run import DEFAULT_METHODS, score

__all__ = ["score", "DEFAULT_METHODS", "Recording", "find_recordings", "read_recording", "Method", "make_method",
           "method_names", "ERRORS", "broad_errors_rad", "error_quat_earth", "rmse_deg", "trial_rmse_deg"]
