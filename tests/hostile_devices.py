"""Misbehaving ring devices on a pty, for the hostile-input tests (issue 15).

Each behaviour answers the host's commands the way a broken board, a bad cable or a hostile
peer might: floods, trickles, wrong sizes, error replies, silence, disconnects. They are
written from the protocol (docs/protocol.md), not from the driver's code.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty

from irring.hardware import protocol as p

SENSORS, MIN_STEP, MAX_STEP, BITS = 12, -2, 2, 12


def line(body: str) -> bytes:
    """One sentence with a correct CRC, whatever its fields say."""
    return p.frame(body.encode())


def info(sensors=SENSORS, bits=BITS, lo=MIN_STEP, hi=MAX_STEP, step_mdeg=1800, num=3,
         den=5) -> bytes:
    return line(f"IRINF,{p.PROTOCOL_VERSION},{sensors},{bits},{step_mdeg},{num},{den},{lo},{hi},hostile")


def counts_for(step: int, n: int = SENSORS) -> list[int]:
    """The counts a well-behaved hostile device sends at ``step`` (known to the test)."""
    return [(500 + 37 * k + 11 * step) % 4096 for k in range(n)]


def scan(seq: int, step: int, n: int = SENSORS, clock0: int = 1000) -> bytes:
    """IRSCN ``seq`` of ``step``, read at ``clock0 + seq`` ms of the device clock."""
    return line(f"IRSCN,{seq},{step},{clock0 + seq},{','.join(map(str, counts_for(step, n)))}")


class HostileDevice:
    """A pty whose far end runs ``behaviour(device, command)`` for each decoded command.

    ``behaviour`` may call :meth:`send` and :meth:`chatter` (a background stream until the
    device is closed). ``link`` is the slave path the host opens.
    """

    def __init__(self, behaviour):
        self.behaviour = behaviour
        self.master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(self.master, False)   # a full pty drops bytes, like a UART overrun
        self.slave = slave
        self.link = os.ttyname(slave)
        self.closed = threading.Event()
        self._fd_lock = threading.Lock()   # no write to an fd number close() gave back
        self.seq = 0
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def send(self, data: bytes) -> None:
        with self._fd_lock:
            if self.closed.is_set():
                return
            try:
                os.write(self.master, data)
            except BlockingIOError:
                pass                      # nobody reads: the bytes are lost
            except OSError:
                self.closed.set()

    def chatter(self, make, every_s: float) -> None:
        """Send ``make()`` every ``every_s`` seconds until closed, in the background."""
        def loop():
            while not self.closed.wait(every_s):
                self.send(make())
        threading.Thread(target=loop, daemon=True).start()

    def hang_up(self) -> None:
        """Close the pty (the host sees a disconnect); safe from any thread."""
        with self._fd_lock:
            if self.master < 0:
                return
            self.closed.set()
            for fd in (self.master, self.slave):
                try:
                    os.close(fd)
                except OSError:
                    pass
            self.master = self.slave = -1

    def _serve(self) -> None:
        decoder = p.Decoder()
        while not self.closed.is_set():
            with self._fd_lock:
                if self.closed.is_set():
                    return
                ready, _, _ = select.select([self.master], [], [], 0)
                try:
                    data = os.read(self.master, 256) if ready else None
                except BlockingIOError:
                    data = None
                except OSError:
                    return
            if data is None:
                time.sleep(0.002)
                continue
            if not data:
                return
            for item in decoder.feed(data):
                if isinstance(item, p.ProtocolError):
                    continue
                if self.closed.is_set():
                    return
                self.behaviour(self, item)

    def close(self) -> None:
        self.hang_up()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=1.0)


# --------------------------------------------------------------------------- behaviours


def _hello(dev, cmd) -> bool:
    if isinstance(cmd, p.Hello):
        dev.send(info())
        return True
    return False


def good(dev, cmd):
    """A correct device: every step, in order, then IRDON."""
    if _hello(dev, cmd):
        return
    if isinstance(cmd, p.SweepCommand):
        for step in range(cmd.from_step, cmd.to_step + 1) if cmd.from_step <= cmd.to_step else \
                range(cmd.from_step, cmd.to_step - 1, -1):
            dev.send(scan(dev.seq, step, clock0=getattr(dev, "clock0", 1000)))
            dev.seq += 1
        dev.send(line(f"IRDON,{dev.seq - 1}"))
    elif isinstance(cmd, p.Stop):
        dev.send(line(f"IRDON,{dev.seq - 1}"))
    elif isinstance(cmd, p.GoTo):
        dev.send(line(f"IRPOS,{cmd.step}"))


def silent(dev, cmd):
    """Answers nothing at all."""


def silent_after_hello(dev, cmd):
    _hello(dev, cmd)


def disconnect_on_sweep(dev, cmd):
    if _hello(dev, cmd):
        return
    if isinstance(cmd, p.SweepCommand):
        dev.send(scan(dev.seq, cmd.from_step))
        dev.hang_up()


def _after_sweep_keep_sending(make, every_s: float, doc: str):
    """A behaviour that answers IRHLO, then after the first IRSWP sends ``make(dev, cmd)``'s
    bytes every ``every_s`` seconds forever (IRSTP ignored)."""
    def behaviour(dev, cmd):
        if _hello(dev, cmd):
            return
        if isinstance(cmd, p.SweepCommand) and not getattr(dev, "flooding", False):
            dev.flooding = True
            data = make(dev, cmd)
            dev.chatter(lambda: data, every_s)
    behaviour.__doc__ = doc
    return behaviour


flood_irpos = _after_sweep_keep_sending(lambda dev, cmd: line("IRPOS,0"), 0.002,
                                        "endless valid IRPOS, never a reading")
repeat_irscn = _after_sweep_keep_sending(lambda dev, cmd: scan(dev.seq, cmd.from_step), 0.005,
                                         "the first step's IRSCN, again and again")
sentence_every_quarter_second = _after_sweep_keep_sending(
    lambda dev, cmd: info(), 0.25, "one valid but useless sentence every 0.25 s")


def trickle(dev, cmd):
    """A correct sweep sent one byte every millisecond: slow, but every step arrives."""
    if _hello(dev, cmd):
        return
    if isinstance(cmd, p.SweepCommand):
        data = b"".join(scan(dev.seq + i, s) for i, s in
                        enumerate(range(cmd.from_step, cmd.to_step + 1)))
        dev.seq += cmd.to_step - cmd.from_step + 1
        data += line(f"IRDON,{dev.seq - 1}")

        def drip():
            for k in range(len(data)):
                if dev.closed.is_set():
                    return
                dev.send(data[k:k + 1])
                time.sleep(0.001)
        threading.Thread(target=drip, daemon=True).start()
    elif isinstance(cmd, p.Stop):
        pass


def out_of_order(dev, cmd):
    """Every step, seq consistent with its step, but sent last step first."""
    if _hello(dev, cmd):
        return
    if isinstance(cmd, p.SweepCommand):
        steps = list(range(cmd.from_step, cmd.to_step + 1))
        base = dev.seq
        for i in reversed(range(len(steps))):
            dev.send(scan(base + i, steps[i]))
        dev.seq += len(steps)
        dev.send(line(f"IRDON,{dev.seq - 1}"))


def wrong_sensor_count(dev, cmd):
    """IRSCN with 11 counts on a ring that announced 12, then IRDON."""
    if _hello(dev, cmd):
        return
    if isinstance(cmd, (p.SweepCommand, p.Stop)):
        if isinstance(cmd, p.SweepCommand):
            for step in range(cmd.from_step, cmd.to_step + 1):
                dev.send(scan(dev.seq, step, n=SENSORS - 1))
                dev.seq += 1
        dev.send(line(f"IRDON,{dev.seq - 1}"))


def done_without_steps(dev, cmd):
    if _hello(dev, cmd):
        return
    if isinstance(cmd, (p.SweepCommand, p.Stop)):
        dev.send(line(f"IRDON,{dev.seq - 1}"))


def error_reply(code: int):
    def behaviour(dev, cmd):
        if _hello(dev, cmd):
            return
        if isinstance(cmd, (p.SweepCommand, p.GoTo)):
            dev.send(line(f"IRERR,{code},{p.ERROR_TEXT.get(code, 'no')}"))
        elif isinstance(cmd, p.Stop):
            dev.send(line(f"IRDON,{dev.seq - 1}"))
    behaviour.__name__ = f"irerr_{code}"
    return behaviour


def refuses_hello(code: int):
    """Answers every IRHLO with IRERR ``code`` (an older firmware, a garbling receiver)."""
    def behaviour(dev, cmd):
        if isinstance(cmd, p.Hello):
            dev.send(line(f"IRERR,{code},{p.ERROR_TEXT[code]}"))
    behaviour.__name__ = f"refuses_hello_{code}"
    return behaviour


def announces(**kw):
    """IRINF with out-of-bounds sizes."""
    def behaviour(dev, cmd):
        if isinstance(cmd, p.Hello):
            dev.send(info(**kw))
    behaviour.__name__ = "announces_" + "_".join(f"{k}{v}" for k, v in kw.items())
    return behaviour


def good_then(behaviour, sweeps: int = 1):
    """A correct device for the first ``sweeps`` IRSWP, then ``behaviour`` (a board that
    breaks down at the second pose)."""
    def switch(dev, cmd):
        if isinstance(cmd, p.SweepCommand):
            dev.sweeps_seen = getattr(dev, "sweeps_seen", 0) + 1
        late = getattr(dev, "sweeps_seen", 0) > sweeps
        (behaviour if late else good)(dev, cmd)
    switch.__name__ = f"good_then_{behaviour.__name__}"
    return switch


def clock_jump(dev, cmd):
    """Two steps whose device clocks lie 2³¹ ms (25 days) apart, the rest lost, then IRDON;
    later passes deliver nothing."""
    if _hello(dev, cmd):
        return
    if isinstance(cmd, p.SweepCommand):
        dev.passes = getattr(dev, "passes", 0) + 1
        if dev.passes == 1:
            for step, t_ms in ((cmd.from_step, 0), (cmd.from_step + 1, 2**31 - 1000)):
                counts = ",".join(map(str, counts_for(step)))
                dev.send(line(f"IRSCN,{dev.seq},{step},{t_ms},{counts}"))
                dev.seq += 1
            dev.seq += abs(cmd.to_step - cmd.from_step) - 1   # sent, but lost on the way
        dev.send(line(f"IRDON,{dev.seq - 1}"))
    elif isinstance(cmd, p.Stop):
        dev.send(line(f"IRDON,{dev.seq - 1}"))


def interrupt_after(n_scans: int):
    """Sends ``n_scans`` IRSCN of the second sweep, then Ctrl-C reaches the host (its main
    thread gets KeyboardInterrupt) and the device goes quiet."""
    import signal

    def second(dev, cmd):
        if isinstance(cmd, p.SweepCommand):
            for step in range(cmd.from_step, cmd.from_step + n_scans):
                dev.send(scan(dev.seq, step))
                dev.seq += 1
            time.sleep(0.05)
            # a real SIGINT to the main thread, as a terminal's Ctrl-C: it ends a blocking
            # read at once (_thread.interrupt_main only set a flag seen after the read's
            # timeout, so a loaded machine let the host time out and retry first)
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
    second.__name__ = f"interrupt_after_{n_scans}"
    return second


def reboots_in_sweep(k: int):
    """A correct device until its ``k``-th IRSWP, where it sends two steps and reboots: it
    forgets the sweep and numbers IRSCN from 0 again (IRDON -1: none sent since boot)."""
    def behaviour(dev, cmd):
        if isinstance(cmd, p.SweepCommand):
            dev.sweeps_seen = getattr(dev, "sweeps_seen", 0) + 1
            if dev.sweeps_seen == k:
                for step in (cmd.from_step, cmd.from_step + 1):
                    dev.send(scan(dev.seq, step))
                    dev.seq += 1
                dev.seq = 0   # the reboot
                return
        good(dev, cmd)
    behaviour.__name__ = f"reboots_in_sweep_{k}"
    return behaviour


def stuck_clock(dev, cmd):
    """A correct device whose clock never moves: every IRSCN carries t_ms 5000."""
    if _hello(dev, cmd):
        return
    if isinstance(cmd, p.SweepCommand):
        d = 1 if cmd.to_step >= cmd.from_step else -1
        for step in range(cmd.from_step, cmd.to_step + d, d):
            dev.send(line(f"IRSCN,{dev.seq},{step},5000,{','.join(map(str, counts_for(step)))}"))
            dev.seq += 1
        dev.send(line(f"IRDON,{dev.seq - 1}"))
    elif isinstance(cmd, p.Stop):
        dev.send(line(f"IRDON,{dev.seq - 1}"))


def garbled_stretch(garbled: int, every_s: float):
    """A correct device behind a noisy link: the first step arrives, then ``garbled``
    sentences with a wrong checksum, one every ``every_s`` s (the link talks all along,
    never silent for longer), then the other steps and IRDON. Each IRSTP it receives is
    counted in ``dev.stops`` and answered with IRDON, as a board ends its sweep."""
    def behaviour(dev, cmd):
        if _hello(dev, cmd):
            return
        if isinstance(cmd, p.Stop):
            dev.stops = getattr(dev, "stops", 0) + 1
            dev.send(line(f"IRDON,{dev.seq - 1}"))
        elif isinstance(cmd, p.SweepCommand):
            steps = list(range(cmd.from_step, cmd.to_step + 1))
            first = scan(dev.seq, steps[0])
            noise = first.replace(first[-4:-2], b"00" if first[-4:-2] != b"00" else b"11")

            def run():
                dev.send(first)
                dev.seq += 1
                for _ in range(garbled):
                    if dev.closed.wait(every_s):
                        return
                    dev.send(noise)
                for step in steps[1:]:
                    dev.send(scan(dev.seq, step))
                    dev.seq += 1
                dev.send(line(f"IRDON,{dev.seq - 1}"))
            threading.Thread(target=run, daemon=True).start()
    behaviour.__name__ = f"garbled_stretch_{garbled}"
    return behaviour


def talks_without_steps(dev, cmd):
    """After IRSWP, a valid IRPOS every 2 ms forever and never a reading; IRSTP is counted
    in ``dev.stops`` and otherwise ignored."""
    if _hello(dev, cmd):
        return
    if isinstance(cmd, p.Stop):
        dev.stops = getattr(dev, "stops", 0) + 1
    elif isinstance(cmd, p.SweepCommand) and not getattr(dev, "flooding", False):
        dev.flooding = True
        dev.chatter(lambda: line("IRPOS,0"), 0.002)


def reboots_between_sweeps(lose_first: bool = False):
    """A correct device that reboots after its first sweep: the second sweep's IRSCN are
    numbered from 0 again (its IRDON too); with ``lose_first`` that sweep's first IRSCN is
    lost on the way."""
    def behaviour(dev, cmd):
        if isinstance(cmd, p.SweepCommand):
            dev.sweeps_seen = getattr(dev, "sweeps_seen", 0) + 1
            if dev.sweeps_seen == 2:
                dev.seq = 0   # the reboot: numbers from 0, its clock from boot
                dev.clock0 = 40
                if lose_first:
                    dev.seq = 1
                    cmd = p.SweepCommand(cmd.from_step + 1, cmd.to_step, cmd.samples,
                                         cmd.settle_ms)
        good(dev, cmd)
    behaviour.__name__ = "reboots_between_sweeps" + ("_losing_the_first_scan" if lose_first
                                                     else "")
    return behaviour
