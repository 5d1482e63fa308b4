"""The ropod smart-wheel (SWMC) EtherCAT process data as numpy structured dtypes.

The drive exchanges packed little-endian C structs: 168 bytes of sensors (TxPDO, slave to
master) and 36 bytes of commands (RxPDO, master to slave) per wheel. The EtherCAT block
moves raw `(wheels, bytes)` uint8 images; the views here give those same bytes named,
typed fields without copying, so a controller reads and writes the image in place.
`sensor_ts` sits at byte 4, so the dtypes carry explicit offsets: a naturally aligned
struct would be wrong. A 1 kHz loop that only needs a few fields per wheel reads or writes
them with one precompiled `record_struct` per image instead of a numpy call per field.
"""

from __future__ import annotations

import enum
import struct

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "TXPDO_BYTES", "RXPDO_BYTES", "TXPDO_DTYPE", "RXPDO_DTYPE", "TXPDO_ENTRY_BITS", "RXPDO_ENTRY_BITS", "Stat1", "Com1",
    "txpdo_view", "rxpdo_view", "pdo_image", "new_tx_image", "new_rx_image", "record_struct",
]

TXPDO_BYTES = 168
RXPDO_BYTES = 36


def _packed(fields: list[tuple[str, str]], itemsize: int) -> np.dtype:
    """A packed (no padding) dtype from (name, format) pairs, checked against the wire size."""
    offsets, at = [], 0
    for _, fmt in fields:
        offsets.append(at)
        at += np.dtype(fmt).itemsize
    if at != itemsize:
        raise AssertionError(f"packed size {at} != {itemsize}")
    return np.dtype({"names": [n for n, _ in fields], "formats": [f for _, f in fields],
                     "offsets": offsets, "itemsize": itemsize})


def _motor(n: int) -> list[tuple[str, str]]:
    names = ["encoder", "velocity", "current_{}_d", "current_{}_q", "current_{}_u", "current_{}_v",
             "current_{}_w", "voltage", "voltage_{}_u", "voltage_{}_v", "voltage_{}_w", "temperature"]
    return [(f"{nm}_{n}" if "{}" not in nm else nm.format(n), "<f4") for nm in names]


# sens_ROPOD_SmartWheel_t: struct '<HHQQ' + 27 f + 'Q' + 8 f
TXPDO_DTYPE = _packed(
    [("status1", "<u2"), ("status2", "<u2"), ("sensor_ts", "<u8"), ("setpoint_ts", "<u8")]
    + _motor(1) + _motor(2)
    + [("encoder_pivot", "<f4"), ("velocity_pivot", "<f4"), ("voltage_bus", "<f4"), ("imu_ts", "<u8")]
    + [(n, "<f4") for n in ("accel_x", "accel_y", "accel_z", "gyro_x", "gyro_y", "gyro_z",
                            "temperature_imu", "pressure")],
    TXPDO_BYTES,
)

# cmd_ROPOD_SmartWheel_t: struct '<HH6fQ'
RXPDO_DTYPE = _packed(
    [("command1", "<u2"), ("command2", "<u2")]
    + [(n, "<f4") for n in ("setpoint1", "setpoint2", "limit1_p", "limit1_n", "limit2_p", "limit2_n")]
    + [("timestamp", "<u8")],
    RXPDO_BYTES,
)


# The bit length of each field in wire order: the PDO mapping a smart wheel reports over CoE.
TXPDO_ENTRY_BITS = tuple(TXPDO_DTYPE.fields[name][0].itemsize * 8 for name in TXPDO_DTYPE.names)
RXPDO_ENTRY_BITS = tuple(RXPDO_DTYPE.fields[name][0].itemsize * 8 for name in RXPDO_DTYPE.names)


class Stat1(enum.IntFlag):
    """`status1` bits reported by the drive (STAT1_*). `status2` has none."""

    ENABLED1 = 0x0001
    ENABLED2 = 0x0002
    ENC_1_OK = 0x0004
    ENC_2_OK = 0x0008
    ENC_PIVOT_OK = 0x0010
    UNDERVOLTAGE = 0x0020
    OVERVOLTAGE = 0x0040
    OVERCURRENT_1 = 0x0080
    OVERCURRENT_2 = 0x0100
    OVERTEMP_1 = 0x0200
    OVERTEMP_2 = 0x0400
    # Composites used by the controller and the simulator.
    ENCODERS_OK = ENC_1_OK | ENC_2_OK | ENC_PIVOT_OK
    FAULTS = UNDERVOLTAGE | OVERVOLTAGE | OVERCURRENT_1 | OVERCURRENT_2 | OVERTEMP_1 | OVERTEMP_2


class Com1(enum.IntFlag):
    """`command1` bits (COM1_*). The mode is a 2-bit field; `command2` has none."""

    ENABLE1 = 0x0001
    ENABLE2 = 0x0002
    MODE_TORQUE = 0x0000  # setpoints are motor currents [A]; limits are velocity bounds
    MODE_DTORQUE = 0x0004  # common / differential current
    MODE_VELOCITY = 0x0008  # setpoints are wheel speeds [rad/s]; limits are current bounds
    MODE_DVELOCITY = 0x000C
    MODE_MASK = 0x000C
    EMERGENCY1 = 0x0010
    EMERGENCY2 = 0x0020
    USE_TS = 0x8000  # execute the setpoint at rxpdo.timestamp (DC time)


def _check_image(image: NDArray[np.uint8], nbytes: int) -> None:
    if image.dtype != np.uint8 or image.ndim != 2 or image.shape[1] != nbytes:
        raise ValueError(f"expected a (wheels, {nbytes}) uint8 image, got {image.dtype} {image.shape}")
    if not image.flags.c_contiguous:
        raise ValueError("a process-data image must be C-contiguous to be viewed in place")


def txpdo_view(image: NDArray[np.uint8]) -> np.ndarray:
    """The (wheels,) TXPDO_DTYPE records sharing memory with a (wheels, 168) sensor image."""
    _check_image(image, TXPDO_BYTES)
    return image.view(TXPDO_DTYPE).reshape(image.shape[0])


def rxpdo_view(image: NDArray[np.uint8]) -> np.ndarray:
    """The (wheels,) RXPDO_DTYPE records sharing memory with a (wheels, 36) command image."""
    _check_image(image, RXPDO_BYTES)
    return image.view(RXPDO_DTYPE).reshape(image.shape[0])


def pdo_image(records: np.ndarray) -> NDArray[np.uint8]:
    """The (wheels, itemsize) uint8 image sharing memory with TxPDO or RxPDO records."""
    if records.dtype not in (TXPDO_DTYPE, RXPDO_DTYPE) or records.ndim != 1:
        raise ValueError(f"expected 1-d TxPDO or RxPDO records, got {records.dtype} {records.shape}")
    if not records.flags.c_contiguous:
        raise ValueError("records must be C-contiguous to be viewed as bytes")
    return records.view(np.uint8).reshape(records.shape[0], records.dtype.itemsize)


def new_tx_image(wheels: int = 4) -> NDArray[np.uint8]:
    """A zeroed sensor image (allocates: for set-up, not for the cycle)."""
    return np.zeros((wheels, TXPDO_BYTES), np.uint8)


def new_rx_image(wheels: int = 4) -> NDArray[np.uint8]:
    """A zeroed command image (allocates: for set-up, not for the cycle)."""
    return np.zeros((wheels, RXPDO_BYTES), np.uint8)


_STRUCT_CODES = {"<u2": "H", "<u8": "Q", "<f4": "f"}


def record_struct(dtype: np.dtype, names: list[str] | tuple[str, ...]) -> struct.Struct:
    """A struct over one TxPDO/RxPDO record holding the named fields, in offset order; the bytes of
    the other fields are pad: skipped when unpacking, written as zero when packing.

    `iter_unpack(image)` then yields each wheel's values, `pack_into(image, wheel * itemsize, ...)`
    writes one wheel.
    """
    unknown = sorted(set(names) - set(dtype.names))
    if unknown:
        raise ValueError(f"no field {', '.join(map(repr, unknown))} in a {dtype.itemsize}-byte PDO record")
    fmt, at = "<", 0
    for offset, name in sorted((dtype.fields[n][1], n) for n in names):
        ftype = dtype.fields[name][0]
        if offset < at:
            raise ValueError(f"field {name!r} overlaps the previous one")
        fmt += f"{offset - at}x" * (offset > at) + _STRUCT_CODES[ftype.str]
        at = offset + ftype.itemsize
    fmt += f"{dtype.itemsize - at}x" * (dtype.itemsize > at)
    return struct.Struct(fmt)
