"""CoLa A requests and replies (§2.2, §3, §6), and the TiM's start-up commands built from them.

A request names its reply: `sRN X` is answered by `sRA X`, and `sFA <code>` answers anything
with a refusal (`ColaDeviceError`). A start-up step is a `Command`: the request, the reply that
answers it and the parameters that mean success. The values and tokens are `cola.py`'s.
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass, field

from hapticop.devices.sick.cola import (
    CONTROL_BYTES,
    LEVEL3_HASH,
    ColaDeviceError,
    ColaError,
    TokenReader,
    encode_int32,
    encode_uint,
    frame,
    show_token,
    unframe,
)

REQUEST_TYPES = {b"sRN": b"sRA", b"sWN": b"sWA", b"sMN": b"sAN", b"sEN": b"sEA", b"sRI": b"sRA"}
REPLY_TYPES = frozenset({b"sRA", b"sWA", b"sAN", b"sMA", b"sEA", b"sSN", b"sFA"})


def password_hash(password: str) -> str:
    """SICK's login hash: MD5, XOR-fold 16 bytes into 4, little-endian uint32, 8 hex digits."""
    digest = hashlib.md5(password.encode("latin-1")).digest()
    folded = bytes(digest[k] ^ digest[k + 4] ^ digest[k + 8] ^ digest[k + 12] for k in range(4))
    return f"{struct.unpack('<I', folded)[0]:08X}"


def request(kind: str, name: str, *params: bytes | str | int) -> bytes:
    """A framed request; ints are encoded as unsigned hex, bytes/str are sent as they are."""
    parts = [kind.encode(), name.encode()]
    for param in params:
        if isinstance(param, bool) or isinstance(param, int):
            parts.append(encode_uint(int(param)))
        elif isinstance(param, str):
            parts.append(param.encode("latin-1"))
        else:
            parts.append(bytes(param))
    return frame(b" ".join(parts))


@dataclass(frozen=True, slots=True)
class Reply:
    """A decoded reply: type, name, and the raw parameters (strings may contain spaces)."""

    kind: bytes  # sRA, sWA, sAN, sMA, sEA, sSN
    name: bytes
    params: bytes

    def reader(self) -> TokenReader:
        return TokenReader(self.params)


def is_text(body: bytes) -> bool:
    """No control bytes: a CoLa A body, not a CoLa B frame or binary noise."""
    return CONTROL_BYTES.search(body) is None


def parse_reply(body: bytes, request_text: str | None = None) -> Reply:
    """Decode a reply body (or framed telegram); `sFA <code>` raises ColaDeviceError."""
    data = bytes(body)
    if data[:1] == b"\x02":
        data = unframe(data)
    if not is_text(data):
        raise ColaError("not CoLa A: control bytes in the body (a CoLa B frame?)")
    reader = TokenReader(data)
    kind = reader.token("command type")
    if kind == b"sFA":
        raise ColaDeviceError(sfa_code(reader), request_text)
    if kind not in REPLY_TYPES:
        raise ColaError(f"unknown reply type {show_token(kind)}")
    name = reader.token("name")
    return Reply(kind, name, reader.rest())


def sfa_code(reader: TokenReader) -> int:
    """The error code of an `sFA` reply whose type the reader has just read; nothing may follow it."""
    code = reader.uint(16, "sFA error code")
    reader.expect_end("the sFA error code")
    return code


def expected_reply(request_body: bytes) -> tuple[bytes, bytes]:
    """(reply type, name) that answers a request: `sRN X` → (`sRA`, `X`); sFA answers any."""
    data = request_body[1:-1] if request_body[:1] == b"\x02" else request_body
    kind, _, rest = data.partition(b" ")
    if kind.startswith(b"sRI") and len(kind) > 3:  # uos/sick_tim's "sRI0"
        return b"sRA", kind[3:]
    if kind not in REQUEST_TYPES:
        raise ValueError(f"not a CoLa request: {data[:20]!r}")
    return REQUEST_TYPES[kind], rest.partition(b" ")[0]


@dataclass(frozen=True, slots=True)
class Command:
    """One start-up step: the request, the reply that answers it, and what counts as success."""

    request: bytes  # framed
    ok: tuple[bytes, ...] | None = None  # accepted reply parameters; None: anything
    refused: str = "unexpected reply"
    reply: tuple[bytes, bytes] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "reply", expected_reply(self.request))

    @property
    def text(self) -> str:
        return self.request[1:-1].decode("latin-1")

    def check(self, reply: Reply) -> None:
        """Raise ColaError when the reply means the step failed."""
        if self.ok is not None and reply.params not in self.ok:
            raise ColaError(f"{self.text!r} → {reply.kind.decode()} {reply.name.decode()} "
                            f"{reply.params.decode('latin-1')!r}: {self.refused}")


@dataclass(frozen=True, slots=True)
class OutputRange:
    """`LMPoutputRange`: angular step and start/stop in 1/10000°, SICK frame (-45°…225° on a TiM)."""

    step: int = 3333
    start: int = -450000
    stop: int = 2250000

    def params(self) -> bytes:
        return b"1 " + encode_uint(self.step, 16) + b" " + encode_int32(self.start) + b" " + encode_int32(self.stop)


@dataclass(frozen=True, slots=True)
class ScanDataConfig:
    """`LMDscandatacfg` (12 tokens, from sick_scan_xd's template; not tested on a TiM561)."""

    rssi: bool = False
    rssi_16bit: bool = True
    device_name: bool = False
    comment: bool = False
    time: bool = False
    every_nth: int = 1

    def params(self) -> bytes:
        flags = (1, 0, int(self.rssi), int(self.rssi_16bit), 0, 0, 0, 0, int(self.device_name),
                 int(self.comment), int(self.time), self.every_nth)
        return b" ".join(encode_uint(v, 16) for v in flags)


def set_access_mode(level: int = 3, hash_hex: str = LEVEL3_HASH) -> Command:
    return Command(request("sMN", "SetAccessMode", level, hash_hex), (b"1",),
                   "login refused: wrong level or password hash")


def set_cola_dialect(binary: bool = False) -> Command:
    return Command(request("sWN", "EIHstCola", int(binary)), (b"",))


def read_device_state() -> Command:
    return Command(request("sRN", "SCdevicestate"), (b"0", b"1"),
                   "device state is not ready/busy (2 = error: reboot it with sMN mSCreboot)")


def set_output_range(output: OutputRange = OutputRange()) -> Command:
    return Command(request("sWN", "LMPoutputRange", output.params()), (b"",))


def set_scan_data_config(config: ScanDataConfig) -> Command:
    return Command(request("sWN", "LMDscandatacfg", config.params()), (b"",))


def start_measurement() -> Command:
    return Command(request("sMN", "LMCstartmeas"), (b"0",), "start of measurement refused")


def run() -> Command:
    return Command(request("sMN", "Run"), (b"1",), "Run (apply settings, log out) refused")


def subscribe_scans(on: bool = True) -> Command:
    return Command(request("sEN", "LMDscandata", int(on)), (b"1" if on else b"0",), "subscription refused")


def startup_sequence(*, configure: bool = True, level: int = 3, hash_hex: str = LEVEL3_HASH,
                     output_range: OutputRange | None = OutputRange(),
                     scan_config: ScanDataConfig | None = None) -> tuple[Command, ...]:
    """The order of sick_scan_xd and docs/devices/sick-tim561.md: login, CoLa A, state, range, (content), start,
    Run, subscribe last (so no scan arrives between configuration replies). With
    `configure=False` only the subscription: a powered TiM measures on its own.
    """
    steps: list[Command] = []
    if configure:
        steps += [set_access_mode(level, hash_hex), set_cola_dialect(False), read_device_state()]
        if output_range is not None:
            steps.append(set_output_range(output_range))
        if scan_config is not None:
            steps.append(set_scan_data_config(scan_config))
        steps += [start_measurement(), run()]
    steps.append(subscribe_scans(True))
    return tuple(steps)
