"""Checking the firmware image a user hands us before it goes near a Falcon.

The image is Novint's (Noncommercial SDK licence): hapticop never ships, embeds or fetches
it. The user gives its path; we load it only if its size and SHA-256 are those of a known
image (docs/devices/falcon.md §3), because uploading arbitrary bytes to the DSP's boot loader
is not something to do by accident. Another image is accepted only when its hash is given
explicitly (`accept_sha256`, the Falcon block's `firmware_sha256` param): the user then
vouches for it, and it still has to look like a C2000 boot table.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

__all__ = ["KnownImage", "KNOWN_IMAGES", "FirmwareError", "read_firmware", "WHERE_TO_FIND"]


@dataclass(frozen=True)
class KnownImage:
    name: str
    size: int
    sha256: str
    origin: str


#: The four images in libnifalcon's `firmware/` (commit f7c727aa), as docs/devices/falcon.md list them.
KNOWN_IMAGES: tuple[KnownImage, ...] = (
    KnownImage("nvent_firmware.bin", 8492, "1119e39c39fab1f37678ea62dfc715b23dd86ee7f13d78f88f707d9f09b896a1",
               "Novint's nVent software; libnifalcon's release firmware"),
    KnownImage("test_firmware.bin", 7324, "b2700d5cd5ca217e48565fb4de5a502a636c53f6e01ebd0cad193e9f84856c6a",
               "NOVINT.BIN from the TestUtilities of Novint's driver package"),
    KnownImage("novint_T0.bin", 7914, "ae838730af34b5822c9c3949859b446614af0410730b832cc17a6ad627ea64a4",
               "libnifalcon firmware/"),
    KnownImage("novint_T2.bin", 7914, "e0ae3598670fa1c8d9277bd6943c99b3152b97c400c46c1c42c60de77ff4e816",
               "libnifalcon firmware/"),
)
BOOT_TABLE_KEY = b"\xaa\x08"  # the C2000 ROM loader's 8-bit boot table key
MAX_SIZE = 64 * 1024
WHERE_TO_FIND = ("a legitimately obtained copy is in Novint's driver installer or in a libnifalcon "
                 "source checkout (firmware/nvent_firmware.bin); hapticop never ships it")


class FirmwareError(ValueError):
    """The firmware file is missing, unreadable or not an image we agreed to upload."""


def _sizes() -> str:
    by_size: dict[int, list[str]] = {}
    for image in KNOWN_IMAGES:
        by_size.setdefault(image.size, []).append(image.name)
    return ", ".join(f"{size} ({' or '.join(names)})" for size, names in sorted(by_size.items(), reverse=True))


def read_firmware(path: str | Path, accept_sha256: str | None = None) -> bytes:
    """The image's bytes, if it is a known Novint image (or has exactly `accept_sha256`).

    Raises FirmwareError naming the file and what is wrong with it.
    """
    path = Path(path).expanduser()
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise FirmwareError(f"firmware file {path} does not exist: {WHERE_TO_FIND}") from None
    except IsADirectoryError:
        raise FirmwareError(f"firmware path {path} is a directory, not the image file") from None
    except OSError as error:
        raise FirmwareError(f"cannot read firmware file {path}: {error.strerror}") from None
    digest = hashlib.sha256(data).hexdigest()
    if accept_sha256 is not None:
        wanted = accept_sha256.strip().lower()
        if digest != wanted:
            raise FirmwareError(f"firmware file {path} has sha256 {digest}, not the accepted {wanted} "
                                "(firmware_sha256): refusing to upload it")
        if not 0 < len(data) <= MAX_SIZE or not data.startswith(BOOT_TABLE_KEY):
            raise FirmwareError(f"firmware file {path} ({len(data)} bytes) is not a C2000 boot table: "
                                f"it must start with AA 08 and hold at most {MAX_SIZE} bytes")
        return data
    if len(data) not in {image.size for image in KNOWN_IMAGES}:
        raise FirmwareError(f"firmware file {path} is {len(data)} bytes; Novint's Falcon images are "
                            f"{_sizes()} bytes: refusing to upload it ({WHERE_TO_FIND})")
    known = next((image for image in KNOWN_IMAGES if image.sha256 == digest), None)
    if known is None:
        raise FirmwareError(f"firmware file {path} has the size of a Falcon image but sha256 {digest}, which "
                            "matches none of Novint's known images: refusing to upload it (if you trust it, "
                            "give its hash as the Falcon's firmware_sha256)")
    return data


def describe(data: bytes) -> str:
    """Which known image these bytes are, for logs."""
    digest = hashlib.sha256(data).hexdigest()
    known = next((image for image in KNOWN_IMAGES if image.sha256 == digest), None)
    return (f"{known.name} ({known.size} bytes)" if known
            else f"an image accepted by hash ({len(data)} bytes, sha256 {digest[:12]}...)")
