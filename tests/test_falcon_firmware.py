"""The firmware file check: only Novint's known images, or one the user vouches for by hash."""

from __future__ import annotations

import hashlib

import pytest

from hapticop.devices.falcon import firmware
from hapticop.devices.falcon.firmware import KNOWN_IMAGES, FirmwareError, KnownImage, read_firmware

IMAGE = b"\xaa\x08" + bytes((i * 13 + 1) & 0xFF for i in range(8490))  # 8492 bytes, like nvent_firmware.bin


def test_known_images_are_the_ones_of_the_notes():
    assert {(i.name, i.size) for i in KNOWN_IMAGES} == {
        ("nvent_firmware.bin", 8492), ("test_firmware.bin", 7324), ("novint_T0.bin", 7914), ("novint_T2.bin", 7914)}
    assert all(len(i.sha256) == 64 and int(i.sha256, 16) >= 0 for i in KNOWN_IMAGES)


def test_a_missing_file_says_where_to_get_one(tmp_path):
    with pytest.raises(FirmwareError, match=r"nope.bin does not exist: .*Novint's driver installer.*never ships"):
        read_firmware(tmp_path / "nope.bin")


def test_a_directory_is_refused(tmp_path):
    with pytest.raises(FirmwareError, match="is a directory"):
        read_firmware(tmp_path)


def test_a_file_of_the_wrong_size_is_refused_naming_the_sizes(tmp_path):
    path = tmp_path / "fw.bin"
    path.write_bytes(IMAGE[:5000])
    with pytest.raises(FirmwareError, match=r"fw.bin is 5000 bytes; .*8492 \(nvent_firmware.bin\).*7914 "
                                            r"\(novint_T0.bin or novint_T2.bin\).*7324"):
        read_firmware(path)


def test_the_right_size_with_an_unknown_hash_is_refused(tmp_path):
    path = tmp_path / "fw.bin"
    path.write_bytes(IMAGE)
    digest = hashlib.sha256(IMAGE).hexdigest()
    with pytest.raises(FirmwareError, match=f"sha256 {digest}, which matches none.*firmware_sha256"):
        read_firmware(path)


def test_a_known_hash_is_accepted(tmp_path, monkeypatch):
    path = tmp_path / "fw.bin"
    path.write_bytes(IMAGE)
    known = KnownImage("test.bin", len(IMAGE), hashlib.sha256(IMAGE).hexdigest(), "this test")
    monkeypatch.setattr(firmware, "KNOWN_IMAGES", (known,))
    assert read_firmware(path) == IMAGE
    assert firmware.describe(IMAGE) == f"test.bin ({len(IMAGE)} bytes)"


def test_an_image_accepted_by_hash_must_match_it_and_look_like_a_boot_table(tmp_path):
    path = tmp_path / "fw.bin"
    path.write_bytes(IMAGE[:3000])
    digest = hashlib.sha256(IMAGE[:3000]).hexdigest()
    assert read_firmware(path, digest.upper()) == IMAGE[:3000]
    with pytest.raises(FirmwareError, match="not the accepted"):
        read_firmware(path, "0" * 64)
    path.write_bytes(b"MZ" + IMAGE[2:3000])
    with pytest.raises(FirmwareError, match="not a C2000 boot table"):
        read_firmware(path, hashlib.sha256(path.read_bytes()).hexdigest())
