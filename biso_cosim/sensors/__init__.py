"""The virtual MPU-9250 (gyro, accelerometer, AK8963 magnetometer) and the magnetic field.

Conventions (the package's): vehicle body axes x forward, y left, z up; world ENU; SI
inside (rad/s, m/s² specific force, µT, s, °C). The chip has its own axes, related to the
body by the mounting rotation ``q_body_chip``; the AK8963 axes relative to the chip axes
are m_x = a_y, m_y = a_x, m_z = −a_z.

Modules: `registers` (configuration registers and chip tables), `profile` (error
parameters and per-seed draws), `dlpf` (filters matching the DLPF tables), `mpu9250`
(the model), `samples` (outputs, raw registers, raw -> SI), `magnetic` (WMM and
disturbances), `gnss` (the virtual GNSS receiver). Parameters and chip facts are data: ``data/*.toml``, ``profiles/*.toml``.

Quick use::

    imu = MPU9250("mpu9250", seed=0)
    s = imu.simulate(omega_b, specific_force_b, mag_b)     # (n, 3) each at 1 kHz
    s.t_s, s.gyro_b, s.accel_b, s.mag_b, s.flags
"""

from biso_cosim.sensors.gnss import GnssFixes, GnssProfile, GnssReceiver, TimeOutage, ZoneOutage
from biso_cosim.sensors.magnetic import SARATOV, Dipole, EarthField, MagneticEnvironment, SteelBeam
from biso_cosim.sensors.mpu9250 import MPU9250
from biso_cosim.sensors.profile import DrawnErrors, Profile, parameter_schema, profile_names
from biso_cosim.sensors.registers import Registers
from biso_cosim.sensors.samples import ImuFlag, ImuSamples, RawSamples, SiReadings, raw_to_si
from biso_cosim.sensors.vibration import MountVibration, VibrationMode

GYRO_SATURATED = ImuFlag.GYRO_SATURATED
ACCEL_SATURATED = ImuFlag.ACCEL_SATURATED
MAG_OVERFLOW = ImuFlag.MAG_OVERFLOW
MAG_OVERRUN = ImuFlag.MAG_OVERRUN
MAG_INVALID = ImuFlag.MAG_INVALID

__all__ = [
    "MPU9250",
    "ImuSamples",
    "RawSamples",
    "SiReadings",
    "Registers",
    "Profile",
    "DrawnErrors",
    "ImuFlag",
    "GYRO_SATURATED",
    "ACCEL_SATURATED",
    "MAG_OVERFLOW",
    "MAG_OVERRUN",
    "MAG_INVALID",
    "raw_to_si",
    "profile_names",
    "parameter_schema",
    "EarthField",
    "MagneticEnvironment",
    "Dipole",
    "SteelBeam",
    "SARATOV",
    "MountVibration",
    "VibrationMode",
]
