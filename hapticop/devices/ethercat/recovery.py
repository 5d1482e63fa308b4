"""SOEM's slave check: bring every slave that left OP back, the way SOEM's examples do.

Each check reads the AL states (`read_state`) and, for each slave not in OP: SAFE-OP+ERR
is acknowledged; SAFE-OP is asked for OP; any other state above NONE is reconfigured;
NONE is confirmed with `state_check` and then marked lost; a lost slave is recovered
(`recover`: found again by position, given back its station address) and then
reconfigured, which leaves it in SAFE-OP for the next check to take to OP. Checking goes on
while any slave is below OP: a reconfigured slave in SAFE-OP returns a full working
counter, so the counter alone would not show it. Every change of a slave's state is
reported to `log(message)`.

SOEM reads every slave's state in one datagram: when that frame is lost or comes back late
(a busy link, a busy emulator), every slave reads NONE at once. Such a silent read is
believed only once the reads have stayed silent for `silent_ms`; until then it changes
nothing and logs nothing, but keeps the check pending (so the segment counts as faulty), and
is read again at the next check. A slave really gone (power, a cut cable) leaves the slaves
before it answering, so only a segment gone as a whole waits for that.

pysoem holds the GIL through `recover`, `reconfig`, `state_check` and `read_state`, and a
recovery attempt on a slave that is still gone waits out its timeouts: so a lost slave is
retried every `retry_lost_ms`, not every cycle, or the exchange thread of the same process
would starve while the wheel is away.
"""

from __future__ import annotations

import time

from hapticop.devices.ethercat.master import AL_ERROR, AL_NONE, AL_OP, AL_SAFEOP, SoemMaster, state_name

__all__ = ["SlaveCheck"]

AL_ACK = 0x10


class SlaveCheck:
    def __init__(self, master: SoemMaster, log, retry_lost_ms: float = 100.0, silent_ms: float = 500.0):
        self.master = master
        self.log = log
        self.retry_lost_ns = int(retry_lost_ms * 1e6)
        self.last_try = [0] * len(master.slaves)
        self.n = len(master.slaves)
        self.previous = [AL_OP] * self.n
        self.lost = [False] * self.n
        self.pending = False  # some slave is below OP: keep checking every cycle
        self.silent_ns = int(silent_ms * 1e6)
        self.silent_since = 0  # when the state reads began to find no slave answering (0: they answer)

    def needed(self) -> bool:
        return self.pending or self.master.last_wkc < self.master.expected_wkc

    def check(self, on_fault=None) -> bool:
        """One pass; True when every slave is in OP. `on_fault()` is called as soon as the
        states show a slave below OP, before the recovery steps (which can take milliseconds)."""
        m = self.master
        with m.lock:
            if not m.opened:
                return False
            m.master.read_state()
            if all(slave.state == AL_NONE for slave in m.slaves):
                now = time.monotonic_ns()
                self.silent_since = self.silent_since or now
                if now - self.silent_since < self.silent_ns:  # most likely a lost frame: read again first
                    self.pending = True
                    return False
            else:
                self.silent_since = 0
            below = []
            for i, slave in enumerate(m.slaves):
                state = slave.state
                if state != self.previous[i]:
                    code = slave.al_status
                    detail = f" (AL code 0x{code:04X} {m.pysoem.al_status_code_to_string(code)})" if code else ""
                    self.log(f"{m.expected[i].name}: {state_name(self.previous[i])} -> {state_name(state)}{detail}")
                    self.previous[i] = state
                if state != AL_OP or self.lost[i]:
                    below.append(i)
            self.pending = bool(below)
            if below and on_fault is not None:
                on_fault()
            for i in below:
                slave = m.slaves[i]
                self._recover(i, slave, m.expected[i].name, slave.state)
            return not below

    def _recover(self, i: int, slave, name: str, state: int) -> None:
        if self.lost[i]:
            if state == AL_NONE:
                now = time.monotonic_ns()
                if now - self.last_try[i] < self.retry_lost_ns:
                    return
                self.last_try[i] = now
                if slave.recover():
                    self.lost[i] = False
                    self.log(f"{name}: recovered")
            else:
                self.lost[i] = False
                self.log(f"{name}: found again")
            return
        if state == AL_SAFEOP | AL_ERROR:
            self.log(f"{name}: acknowledging the error")
            slave.state = AL_SAFEOP | AL_ACK
            slave.write_state()
        elif state == AL_SAFEOP:
            slave.state = AL_OP
            slave.write_state()
        elif state > AL_NONE:
            if slave.reconfig():
                self.log(f"{name}: reconfigured")
        else:
            slave.state_check(AL_OP, 2000)  # confirm it is gone before marking it lost
            if slave.state == AL_NONE:
                self.lost[i] = True
                self.log(f"{name}: lost")
