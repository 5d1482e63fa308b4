"""Split a CoLa A byte stream into telegrams, whatever the socket hands over.

TCP gives no message boundaries: one 3.4 kB scan arrives in several segments, and one
`recv` may hold several telegrams. STX and ETX never occur inside a body, so they alone
delimit frames (docs/devices/sick-tim561.md §8):

1. drop bytes until an STX (counted in `discarded_bytes`);
2. collect until an ETX, which ends the frame;
3. an STX before the ETX means the frame so far was broken: drop it, restart at the new STX;
4. a frame that grows past `max_telegram` without an ETX is dropped, and we hunt for STX again,
   so the buffer stays bounded whatever a broken peer sends.
"""

from __future__ import annotations

from collections.abc import Iterator

MAX_TELEGRAM = 64 * 1024  # well above the largest TiM561 frame (7.1 kB with 16-bit RSSI)


class TelegramReader:
    """Feed it chunks, iterate it for complete bodies (without STX/ETX)."""

    def __init__(self, max_telegram: int = MAX_TELEGRAM):
        if max_telegram < 2:
            raise ValueError("max_telegram must hold at least STX and ETX")
        self.max_telegram = max_telegram
        self._buffer = bytearray()  # empty, or starts with STX
        self._searched = 1  # bytes after the STX already known to hold neither STX nor ETX
        self.discarded_bytes = 0  # garbage between frames, broken frames, overflows
        self.broken_frames = 0  # a frame cut short by a new STX
        self.overflows = 0  # a frame dropped for growing past max_telegram
        self.telegrams = 0

    @property
    def buffered(self) -> int:
        """Bytes of an incomplete frame held back (at most max_telegram)."""
        return len(self._buffer)

    def feed(self, chunk: bytes | bytearray | memoryview) -> None:
        """Append received bytes; garbage outside frames is dropped right away."""
        if not self._buffer:
            data = chunk if isinstance(chunk, (bytes, bytearray)) else bytes(chunk)
            start = data.find(b"\x02")
            if start < 0:
                self.discarded_bytes += len(chunk)
                return
            self.discarded_bytes += start
            self._buffer += memoryview(data)[start:]
            self._searched = 1
        else:
            self._buffer += chunk
        self._bound()

    def __iter__(self) -> Iterator[bytes]:
        """Complete bodies, in order, until the buffer holds no complete frame."""
        while True:
            body = self.next()
            if body is None:
                return
            yield body

    def push(self, chunk: bytes | bytearray | memoryview) -> Iterator[bytes]:
        """`feed(chunk)` then iterate."""
        self.feed(chunk)
        return iter(self)

    def next(self) -> bytes | None:
        """The next complete body, or None."""
        buffer = self._buffer
        while buffer:
            end = buffer.find(b"\x03", self._searched)
            restart = buffer.find(b"\x02", self._searched, end if end >= 0 else len(buffer))
            if restart >= 0:  # a new STX before any ETX: the frame so far is broken
                self.discarded_bytes += restart
                self.broken_frames += 1
                del buffer[:restart]
                self._searched = 1
                continue
            if end < 0:
                self._searched = len(buffer)
                return None
            body = bytes(buffer[1:end])
            del buffer[:end + 1]
            self._searched = 1
            self._skip_to_stx()
            self._bound()
            self.telegrams += 1
            return body
        return None

    def reset(self) -> None:
        """Forget a partial frame (after a reconnect); it counts as discarded."""
        self.discarded_bytes += len(self._buffer)
        self._buffer.clear()
        self._searched = 1

    def _skip_to_stx(self) -> None:
        start = self._buffer.find(b"\x02")
        if start < 0:
            self.discarded_bytes += len(self._buffer)
            self._buffer.clear()
        elif start:
            self.discarded_bytes += start
            del self._buffer[:start]

    def _bound(self) -> None:
        """Drop frames that grew past max_telegram without an ETX (complete ones stay)."""
        buffer, limit = self._buffer, self.max_telegram
        while len(buffer) > limit:
            end = buffer.find(b"\x03", self._searched, limit)
            restart = buffer.find(b"\x02", self._searched, end if end >= 0 else limit)
            if restart >= 0:
                self.broken_frames += 1
                cut = restart
            elif end >= 0:
                return  # a complete frame within the limit: next() takes it, then we bound again
            else:  # no ETX within the limit: drop this frame and its tail up to the next STX
                self.overflows += 1
                cut = buffer.find(b"\x02", limit)
                if cut < 0:
                    cut = len(buffer)
            self.discarded_bytes += cut
            del buffer[:cut]
            self._searched = 1
