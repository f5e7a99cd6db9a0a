"""The plug-in for other vehicle simulators: the virtual MPU-9250 and attitude estimators of
biso_cosim, fed with a host simulator's vehicle truth tick by tick.

::

    from biso_cosim.plugin import HostFrames, ImuPlugin, Mounting

    imu = ImuPlugin(tick_s=0.001, frames=HostFrames("NED", "FRD", "xyzw"), seed=0,
                    mounting=Mounting(position_m=(0.4, 0.0, -0.2)), estimators=["biso_plus"])
    for each physics tick of the host:
        out = imu.step(t, q_wb, omega_b, accel_w=a_w)        # host frames, reference point
        out.gyro_b, out.accel_b, out.mag_b                    # samples latched on this tick
        out.estimates["biso_plus"].q_wb, out.latest()         # estimates after them
        out.estimates["biso_plus"].errors_deg                 # against the given truth

Semantics (the reference for every implementation of the plug-in, e.g. the FMU):

* **Timing.** The truth of tick k is the chip's input sample k, at host time
  t_k = t₀ + k·tick_s (t₀ the first tick's time; ticks come without gaps, each within
  ``TIME_TOL``·tick_s of its time). Between ticks the chip interpolates the truth linearly;
  before t₀ it is taken as constant (the chip starts settled). The chip samples at its
  internal rate and latches its outputs at t₀ + m/ODR, m = 0, 1, ...; a tick returns the
  samples latched in (t_{k−1}, t_k] (k = 0: the sample at t₀), so at 1 kHz ticks and the
  default 200 Hz ODR every fifth tick returns one sample and the others none.
* **Truth at a sample.** The attitude at a sample's instant is the normalised linear
  interpolation (nlerp, on the shorter arc) of the attitudes of the two ticks around it;
  the velocity is interpolated linearly. The errors are the estimate minus this truth.
* **Outputs.** Readings (SI, host body axes), raw register words (chip axes), the chip's
  flags; for each estimator the attitude after each sample (host conventions), its flags,
  its gyro bias (if it estimates one) and its errors (roll, pitch, compass heading, total,
  degrees). Each estimator runs at the ODR on the samples, with the chip's flag bits as
  ``imu_flags`` where it takes them (as in the co-simulation; fmu/imu_plugin.py does not
  pass them yet: the numbers are the same while no flag is set).
* **Reused outputs.** ``reuse_outputs=True``: the arrays a call returns are views of the
  plug-in's buffers, written again by the next call (one ``PluginOutput`` per number of
  samples, made once); ``PluginOutput.copy()`` keeps one. The numbers are the same.
* **Lever arm.** The chip at r from the host's reference point (body axes) feels the
  specific force f + ω̇ × r + ω × (ω × r) and sits at p + q ∘ r ∘ q*. ω̇ is the host's
  ``alpha_b`` when given, else the slope (ω_k − ω_{k−1})/tick_s of the linear interpolation
  the chip applies between the ticks (zero at the first tick): a backward difference, late
  by half a tick.
* **Seeding.** ``seed`` draws the part (turn-on biases, scale factors, ...) and its noise:
  the same seed and truth give the same readings and estimates, bit for bit.
* **Streaming = batch.** Any split of a run into calls (one tick or blocks of ticks) gives
  the same outputs, bit for bit; for one block they equal ``MPU9250.simulate`` on the whole
  truth array followed by each estimator's batch ``update``.
* **State.** ``get_state``/``set_state`` copy and restore everything that changes
  (sensor, estimators, clock, previous tick); ``reset`` goes back to before the first tick.
* **Bad input** (NaN or inf, a quaternion whose norm is not 1 ± ``QUAT_NORM_TOL``, a tick
  out of time, a tick period the chip's rates cannot take, an unknown frame name, wrong
  shapes) raises ValueError naming the argument and changes nothing.

Frames: ``HostFrames`` (``adapter.py``). Bridge to a real simulator: ``pybullet_racecar``
(the ``pybullet`` extra). Guide and recipes for CARLA, BeamNG and Gazebo: docs/plugin.md.
"""

from biso_cosim.plugin._kernels import QUAT_NORM_TOL, TIME_TOL
from biso_cosim.plugin.adapter import BODIES, QUATERNION_ORDERS, WORLDS, HostFrames
from biso_cosim.plugin.imu_plugin import ImuPlugin, Mounting, PluginState
from biso_cosim.plugin.output import EstimateOutput, PluginOutput

__all__ = [
    "ImuPlugin",
    "HostFrames",
    "Mounting",
    "PluginState",
    "PluginOutput",
    "EstimateOutput",
    "WORLDS",
    "BODIES",
    "QUATERNION_ORDERS",
    "QUAT_NORM_TOL",
    "TIME_TOL",
]
