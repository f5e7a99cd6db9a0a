"""The MPU-9250 configuration registers that shape its output, and what they imply.

`Registers` holds the register fields a driver writes (values as in the register map,
RM-MPU-9250A-00 Rev 1.4); its properties derive the rates, full scales and filter entries
from the chip tables in ``data/mpu9250.toml``. Nothing here depends on a particular part:
per-part errors live in the profiles.
"""

from __future__ import annotations

import dataclasses
import functools
import tomllib
from importlib import resources
from typing import Any, Mapping

from biso_cosim.units import DEG, G0

__all__ = ["Registers", "chip_tables", "DlpfEntry", "MAG_MODES"]

# AK8963 CNTL1 MODE codes accepted by the model (external trigger and self-test are not modelled).
MAG_MODES = {
    0x0: "power-down",
    0x1: "single (triggered by the driver every 1 + I2C_MST_DLY samples)",
    0x2: "continuous 1 (8 Hz)",
    0x6: "continuous 2 (100 Hz)",
}


@functools.cache
def chip_tables() -> dict[str, Any]:
    """The chip facts of ``data/mpu9250.toml`` (register tables, conversion constants)."""
    text = resources.files("biso_cosim.sensors").joinpath("data/mpu9250.toml").read_text("utf-8")
    return tomllib.loads(text)


@dataclasses.dataclass(frozen=True)
class DlpfEntry:
    """One row of a DLPF table: -3 dB bandwidth, delay and the internal rate it runs at."""

    bandwidth_hz: float
    delay_s: float
    rate_hz: float


def _check_int(name: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"registers.{name} must be an int in [{low}, {high}], got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"registers.{name} must be in [{low}, {high}], got {value}")
    return value


@dataclasses.dataclass(frozen=True)
class Registers:
    """Register fields of the MPU-9250 and its AK8963 that the model uses.

    Defaults: a common vehicle configuration: gyro ±250 °/s, accel ±4 g, gyro DLPF 41 Hz
    (DLPF_CFG = 3), accel DLPF 44.8 Hz (A_DLPF_CFG = 3), SMPLRT_DIV = 4 (200 Hz output from
    the 1 kHz internal rate), AK8963 continuous mode 2 (100 Hz) at 16 bit.

    Attributes:
        smplrt_div: SMPLRT_DIV (reg 25), 0..255; ODR = 1 kHz / (1 + SMPLRT_DIV) when the DLPF
            is in use (FCHOICE_B = 0 and 0 < DLPF_CFG < 7), else ignored.
        dlpf_cfg: CONFIG.DLPF_CFG (reg 26), 0..7.
        gyro_fchoice_b: GYRO_CONFIG.FCHOICE_B (reg 27 bits 1:0), 0..3; non-zero bypasses the
            DLPF (8800 Hz if bit 0 is set, 3600 Hz for 0b10, both at 32 kHz).
        gyro_fs_sel: GYRO_CONFIG.GYRO_FS_SEL, 0..3 for ±250/500/1000/2000 °/s.
        accel_fs_sel: ACCEL_CONFIG.ACCEL_FS_SEL (reg 28), 0..3 for ±2/4/8/16 g.
        a_dlpf_cfg: ACCEL_CONFIG2.A_DLPFCFG (reg 29), 0..7.
        accel_fchoice_b: ACCEL_CONFIG2.ACCEL_FCHOICE_B, 0 or 1 (1: 1.13 kHz at 4 kHz).
        mag_mode: AK8963 CNTL1.MODE: 0x0 power-down, 0x1 single measurement (the driver's
            I2C master writes CNTL1 after each read, every 1 + I2C_MST_DLY output samples;
            the data is ready 7.2 ms later), 0x2 continuous 1 (8 Hz), 0x6 continuous 2 (100 Hz).
        mag_bit16: AK8963 CNTL1.BIT: True for 16-bit (0.15 µT/LSB), False for 14-bit (0.6).
        i2c_mst_dly: I2C_SLV4_CTRL.I2C_MST_DLY (reg 52), 0..31: with I2C_MST_DELAY_CTRL set
            for the slave, it is accessed every 1 + I2C_MST_DLY samples (single mode only).
    """

    smplrt_div: int = 4
    dlpf_cfg: int = 3
    gyro_fchoice_b: int = 0
    gyro_fs_sel: int = 0
    accel_fs_sel: int = 1
    a_dlpf_cfg: int = 3
    accel_fchoice_b: int = 0
    mag_mode: int = 0x6
    mag_bit16: bool = True
    i2c_mst_dly: int = 0

    def __post_init__(self) -> None:
        _check_int("smplrt_div", self.smplrt_div, 0, 255)
        _check_int("dlpf_cfg", self.dlpf_cfg, 0, 7)
        _check_int("gyro_fchoice_b", self.gyro_fchoice_b, 0, 3)
        _check_int("gyro_fs_sel", self.gyro_fs_sel, 0, 3)
        _check_int("accel_fs_sel", self.accel_fs_sel, 0, 3)
        _check_int("a_dlpf_cfg", self.a_dlpf_cfg, 0, 7)
        _check_int("accel_fchoice_b", self.accel_fchoice_b, 0, 1)
        _check_int("mag_mode", self.mag_mode, 0, 15)
        if self.mag_mode not in MAG_MODES:
            known = ", ".join(f"0x{k:X} ({v})" for k, v in MAG_MODES.items())
            raise ValueError(f"registers.mag_mode must be one of {known}, got 0x{self.mag_mode:X}")
        _check_int("i2c_mst_dly", self.i2c_mst_dly, 0, 31)
        if not isinstance(self.mag_bit16, bool):
            raise TypeError(f"registers.mag_bit16 must be a bool, got {self.mag_bit16!r}")

    @classmethod
    def coerce(cls, registers: "Registers | Mapping[str, Any] | None") -> "Registers":
        """A `Registers` from itself, a dict of field values, or None (the defaults)."""
        if registers is None:
            return cls()
        if isinstance(registers, Registers):
            return registers
        if isinstance(registers, Mapping):
            names = {f.name for f in dataclasses.fields(cls)}
            unknown = sorted(set(registers) - names)
            if unknown:
                raise ValueError(f"registers: unknown field(s) {unknown}; known: {sorted(names)}")
            return cls(**registers)
        raise TypeError(f"registers must be a Registers, a dict or None, got {type(registers).__name__}")

    # ---- gyro --------------------------------------------------------------------------

    @property
    def gyro_dlpf(self) -> DlpfEntry:
        """Gyro DLPF table entry in use (bandwidth, delay, internal rate)."""
        row = self._gyro_row()
        return DlpfEntry(row[0], row[1] * 1e-3, row[2])

    @property
    def temperature_dlpf(self) -> DlpfEntry:
        """Temperature-sensor filter entry of the same CONFIG row (its own rate is the gyro's)."""
        row = self._gyro_row()
        return DlpfEntry(row[3], row[4] * 1e-3, row[2])

    def _gyro_row(self) -> list[float]:
        t = chip_tables()["gyro_dlpf"]
        if self.gyro_fchoice_b & 0b01:
            return t["fchoice_b_x1"]
        if self.gyro_fchoice_b == 0b10:
            return t["fchoice_b_10"]
        return t["dlpf_cfg"][self.dlpf_cfg]

    @property
    def gyro_full_scale(self) -> float:
        """Gyro full scale in rad/s (the nominal ± range)."""
        return chip_tables()["gyro"]["full_scale_dps"][self.gyro_fs_sel] * DEG

    @property
    def gyro_lsb_per_unit(self) -> float:
        """Gyro sensitivity in LSB per rad/s."""
        return chip_tables()["gyro"]["sensitivity_lsb_per_dps"][self.gyro_fs_sel] / DEG

    # ---- accelerometer -----------------------------------------------------------------

    @property
    def accel_dlpf(self) -> DlpfEntry:
        """Accelerometer DLPF table entry in use."""
        t = chip_tables()["accel_dlpf"]
        row = t["accel_fchoice_b_1"] if self.accel_fchoice_b else t["a_dlpf_cfg"][self.a_dlpf_cfg]
        return DlpfEntry(row[0], row[1] * 1e-3, row[2])

    @property
    def accel_full_scale(self) -> float:
        """Accelerometer full scale in m/s²."""
        return chip_tables()["accel"]["full_scale_g"][self.accel_fs_sel] * G0

    @property
    def accel_lsb_per_unit(self) -> float:
        """Accelerometer sensitivity in LSB per m/s²."""
        return chip_tables()["accel"]["sensitivity_lsb_per_g"][self.accel_fs_sel] / G0

    # ---- timing ------------------------------------------------------------------------

    @property
    def uses_sample_rate_divider(self) -> bool:
        """SMPLRT_DIV acts only with the DLPF on (FCHOICE_B = 0) and 0 < DLPF_CFG < 7."""
        return self.gyro_fchoice_b == 0 and 0 < self.dlpf_cfg < 7

    @property
    def output_rate_hz(self) -> float:
        """Output data rate (ODR) of accel, gyro and temperature registers in Hz."""
        if self.uses_sample_rate_divider:
            return chip_tables()["sample_rate"]["dlpf_internal_rate_hz"] / (1 + self.smplrt_div)
        return self.gyro_dlpf.rate_hz

    @property
    def gyro_samples_per_output(self) -> int:
        """Gyro internal samples per output sample."""
        return 1 + self.smplrt_div if self.uses_sample_rate_divider else 1

    # ---- AK8963 ------------------------------------------------------------------------

    @property
    def mag_rate_hz(self) -> float:
        """AK8963 measurement rate in Hz (0 when powered down; the trigger rate in single mode)."""
        ak = chip_tables()["ak8963"]
        if self.mag_mode == ak["mode_single"]:
            return self.output_rate_hz / (1 + self.i2c_mst_dly)
        if self.mag_mode == ak["mode_continuous_1"]:
            return ak["continuous_1_rate_hz"]
        if self.mag_mode == ak["mode_continuous_2"]:
            return ak["continuous_2_rate_hz"]
        return 0.0

    @property
    def mag_resolution_ut(self) -> float:
        """AK8963 resolution in µT/LSB (before the ASA adjustment)."""
        ak = chip_tables()["ak8963"]
        return ak["resolution_16bit_ut"] if self.mag_bit16 else ak["resolution_14bit_ut"]

    @property
    def mag_max_code(self) -> int:
        """Largest AK8963 output code magnitude (32760 at 16 bit, 8190 at 14 bit)."""
        ak = chip_tables()["ak8963"]
        return ak["max_code_16bit"] if self.mag_bit16 else ak["max_code_14bit"]

    def describe(self) -> str:
        """One line per setting, in datasheet terms."""
        g, a = self.gyro_dlpf, self.accel_dlpf
        mag = MAG_MODES[self.mag_mode]
        return "\n".join(
            [
                f"gyro  ±{self.gyro_full_scale / DEG:g} °/s, DLPF {g.bandwidth_hz:g} Hz / {g.delay_s * 1e3:g} ms at {g.rate_hz:g} Hz",
                f"accel ±{self.accel_full_scale / G0:g} g, DLPF {a.bandwidth_hz:g} Hz / {a.delay_s * 1e3:g} ms at {a.rate_hz:g} Hz",
                f"ODR   {self.output_rate_hz:g} Hz (SMPLRT_DIV {'used' if self.uses_sample_rate_divider else 'ignored'})",
                f"AK8963 {mag}, {16 if self.mag_bit16 else 14}-bit ({self.mag_resolution_ut:g} µT/LSB)",
            ]
        )

