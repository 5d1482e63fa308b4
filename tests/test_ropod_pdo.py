"""The smart-wheel process-data dtypes against the published layout, and their zero-copy views."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from hapticop.devices.ropod.pdo import (
    RXPDO_BYTES,
    RXPDO_DTYPE,
    TXPDO_BYTES,
    TXPDO_DTYPE,
    Com1,
    Stat1,
    new_rx_image,
    new_tx_image,
    pdo_image,
    record_struct,
    rxpdo_view,
    txpdo_view,
)

from .test_ropod_data import load

_TYPES = {"uint16": "<u2", "uint64": "<u8", "float32 (IEEE754)": "<f4"}


@pytest.mark.parametrize(("section", "dtype"), [("txpdo_inputs_slave_to_master", TXPDO_DTYPE),
                                                 ("rxpdo_outputs_master_to_slave", RXPDO_DTYPE)])
def test_layout_matches_the_published_offsets_sizes_and_types(section, dtype):
    spec = load("pdo")[section]
    assert dtype.itemsize == spec["size_bytes"]
    assert list(dtype.names) == [f["name"] for f in spec["fields"]]
    for f in spec["fields"]:
        ftype, offset = dtype.fields[f["name"]]
        assert (offset, ftype.itemsize, ftype.str) == (f["offset"], f["size"], _TYPES[f["type"]]), f["name"]


def test_sizes_equal_the_python_struct_formats():
    enc = load("pdo")["encoding"]
    assert struct.calcsize(enc["python_struct_format_txpdo"]) == TXPDO_BYTES == 168
    assert struct.calcsize(enc["python_struct_format_rxpdo"]) == RXPDO_BYTES == 36


def test_bit_constants_match_the_published_ones():
    spec = load("pdo")
    stat1 = {int(k, 16): v for k, v in spec["STAT1_bits"].items() if not k.startswith("_")}
    assert stat1 == {int(b): b.name for b in Stat1 if b.name in stat1.values()}
    com1 = spec["COM1_bits"]
    assert {int(k, 16): v.split()[0] for k, v in com1.items() if k.startswith("0x")} == {
        0x0001: "ENABLE1", 0x0002: "ENABLE2", 0x0010: "EMERGENCY1", 0x0020: "EMERGENCY2", 0x8000: "USE_TS"}
    assert {int(getattr(Com1, k)) for k in ("ENABLE1", "ENABLE2", "EMERGENCY1", "EMERGENCY2", "USE_TS")} == {
        0x1, 0x2, 0x10, 0x20, 0x8000}
    modes = com1["bits 2-3 (mask 0x000C) MODE"]
    assert {int(k, 16): v for k, v in modes.items()} == {
        int(Com1.MODE_TORQUE): "TORQUE", int(Com1.MODE_DTORQUE): "DTORQUE",
        int(Com1.MODE_VELOCITY): "VELOCITY", int(Com1.MODE_DVELOCITY): "DVELOCITY"}
    assert int(Com1.MODE_MASK) == 0x000C


def test_hand_packed_sensor_image_decodes_to_its_values():
    fmt = load("pdo")["encoding"]["python_struct_format_txpdo"]
    floats = [0.5 * i - 3.0 for i in range(27)]
    imu = [9.75, -0.25, 9.81, 0.125, -0.5, 1.5, 301.0, 101325.0]
    raw = [struct.pack(fmt, 0x001F, 0, 123_456_789_012, 2**63 + 5, *floats, 42, *imu),
           struct.pack(fmt, 0x0480, 7, 1, 2, *[-f for f in floats], 2**64 - 1, *imu)]
    image = np.frombuffer(b"".join(raw), np.uint8).reshape(2, TXPDO_BYTES).copy()
    rec = txpdo_view(image)
    assert rec.shape == (2,)
    assert rec["status1"].tolist() == [0x001F, 0x0480]
    assert Stat1(int(rec["status1"][0])) & Stat1.ENCODERS_OK == Stat1.ENCODERS_OK
    assert Stat1(int(rec["status1"][1])) == Stat1.OVERCURRENT_1 | Stat1.OVERTEMP_2
    assert rec["status2"].tolist() == [0, 7]
    assert rec["sensor_ts"].tolist() == [123_456_789_012, 1]
    assert rec["setpoint_ts"].tolist() == [2**63 + 5, 2]
    assert rec["encoder_1"][0] == -3.0 and rec["velocity_1"][0] == -2.5
    assert rec["temperature_1"][0] == 2.5 and rec["encoder_2"][0] == 3.0
    assert rec["encoder_pivot"].tolist() == [9.0, -9.0]
    assert rec["velocity_pivot"][0] == 9.5 and rec["voltage_bus"][0] == 10.0
    assert rec["imu_ts"].tolist() == [42, 2**64 - 1]
    assert rec["gyro_z"][1] == 1.5 and rec["pressure"][0] == 101325.0


def test_command_image_written_through_the_view_unpacks_with_struct():
    image = new_rx_image(4)
    rec = rxpdo_view(image)
    rec["command1"] = Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_TORQUE
    rec["setpoint1"] = [1.5, -2.0, 0.25, 3.0]
    rec["setpoint2"] = -rec["setpoint1"]
    rec["limit1_p"], rec["limit1_n"] = 10.0, -10.0
    rec["timestamp"] = 2**40 + 3
    fmt = load("pdo")["encoding"]["python_struct_format_rxpdo"]
    unpacked = struct.unpack(fmt, image[1].tobytes())
    assert unpacked == (3, 0, -2.0, 2.0, 10.0, -10.0, 0.0, 0.0, 2**40 + 3)


def test_views_share_memory_both_ways():
    rng = np.random.default_rng(7)
    image = rng.integers(0, 256, (4, TXPDO_BYTES), dtype=np.uint8)
    before = image.copy()
    rec = txpdo_view(image)
    back = pdo_image(rec)
    assert back.shape == image.shape and back.dtype == np.uint8
    assert np.shares_memory(rec, image) and np.shares_memory(back, image)
    assert np.array_equal(back, before)
    rec["velocity_2"][3] = 1.25
    assert image[3, 72:76].tobytes() == struct.pack("<f", 1.25)
    image[0, 0:2] = (0x10, 0x00)
    assert rec["status1"][0] == 0x0010
    cmd = new_rx_image(3)
    assert np.shares_memory(pdo_image(rxpdo_view(cmd)), cmd)


def test_record_structs_read_and_write_the_named_fields_of_each_wheel():
    rng = np.random.default_rng(11)
    image = rng.integers(0, 256, (4, TXPDO_BYTES), dtype=np.uint8)
    rec = txpdo_view(image)
    rec["encoder_pivot"] = rng.normal(size=4)  # finite floats where the struct reads floats
    rec["velocity_1"], rec["velocity_2"] = rng.normal(size=4), rng.normal(size=4)
    names = ("velocity_2", "status1", "encoder_pivot", "velocity_1")  # any order: values come in offset order
    reader = record_struct(TXPDO_DTYPE, names)
    assert reader.size == TXPDO_BYTES
    expected = [tuple(r[n].item() for n in ("status1", "velocity_1", "velocity_2", "encoder_pivot")) for r in rec]
    assert list(reader.iter_unpack(image)) == expected
    writer = record_struct(TXPDO_DTYPE, ("status1", "sensor_ts", "gyro_z"))
    writer.pack_into(image, 2 * TXPDO_BYTES, 0x1F, 2**60 + 1, 0.5)
    assert (rec["status1"][2], rec["sensor_ts"][2], rec["gyro_z"][2]) == (0x1F, 2**60 + 1, 0.5)
    assert not rec["status2"][2] and not rec["pressure"][2]  # the other fields of that wheel are zeroed
    assert record_struct(RXPDO_DTYPE, RXPDO_DTYPE.names).format == "<HHffffffQ"
    with pytest.raises(ValueError, match="'no_such_field'"):
        record_struct(RXPDO_DTYPE, ("setpoint1", "no_such_field"))


def test_malformed_images_are_refused():
    with pytest.raises(ValueError):
        txpdo_view(np.zeros((4, 172), np.uint8))  # the KELO successor's size
    with pytest.raises(ValueError):
        rxpdo_view(np.zeros((4, 36), np.float32))
    with pytest.raises(ValueError):
        txpdo_view(new_tx_image(4)[::2])
    with pytest.raises(ValueError):
        pdo_image(np.zeros(4))
