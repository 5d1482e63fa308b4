"""The firmware file check: only Novint's known images, or one the user vouches for by hash."""

from __future__ import annotations

import hashlib

import pytest

from hapticop.devices.falcon import firmware
from hapticop.devices.falcon.firmware import KNOWN_IMAGES, FirmwareError, KnownImage, read_firmware

IMAGE = b"\xaa\x08" + bytes((i * 13 + 1) & 0xFF for i in range(8490))  # 8492 bytes, like nvent_firmware.bin


# The images as libnifalcon publishes them in its `firmware/` directory (github.com/libnifalcon/libnifalcon,
# commit f7c727aa): the git blob id each file has in that commit's tree (what `git ls-tree` and GitHub show
# for it), its size, and the SHA-256 we computed from that blob. Written here by hand from that tree, not from
# our module, so a wrong or made-up hash in KNOWN_IMAGES fails the test below.
PUBLISHED = {
    "nvent_firmware.bin": ("62508b027235510880a57cab7a0dbaff6c4a263c", 8492,
                           "1119e39c39fab1f37678ea62dfc715b23dd86ee7f13d78f88f707d9f09b896a1"),
    "test_firmware.bin": ("389cf1adc13f41a42e08c6d5675f708b146ae5a9", 7324,
                          "b2700d5cd5ca217e48565fb4de5a502a636c53f6e01ebd0cad193e9f84856c6a"),
    "novint_T0.bin": ("758570c1fb0ebdba39bc15d6cd17c02d7a14b02a", 7914,
                      "ae838730af34b5822c9c3949859b446614af0410730b832cc17a6ad627ea64a4"),
    "novint_T2.bin": ("1700777d3cf4d0aa45ede70d21edf37a6c7ad429", 7914,
                      "e0ae3598670fa1c8d9277bd6943c99b3152b97c400c46c1c42c60de77ff4e816"),
}


def test_known_images_are_the_published_ones():
    assert {i.name: (i.size, i.sha256) for i in KNOWN_IMAGES} == {
        name: (size, sha256) for name, (_blob, size, sha256) in PUBLISHED.items()}


def test_the_docs_list_the_same_hashes():
    from .conftest import ROOT

    table = (ROOT / "docs" / "devices" / "falcon.md").read_text()
    for name, (_blob, size, sha256) in PUBLISHED.items():
        assert f"| `{name}` | {size} | `{sha256}` |" in table, name


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
