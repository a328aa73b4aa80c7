"""The reference firmware (firmware/, C): its host build serves the same core on a real pty,
and SerialRing, the Python protocol module and `irring drive` must get exactly what
firmware/README.md promises; the AVR image must fit the ATmega328P and hit 115200 baud."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import serial
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from irring.designs import PAPER_RING
from irring.hardware import SerialRing
from irring.hardware import protocol as p

ROOT = Path(__file__).resolve().parents[1]
FIRMWARE = ROOT / "firmware"
HOST = FIRMWARE / "build" / "irring-host"
SPEED = 20            # the host device's clock runs 20× wall time: a full sweep ≈ 0.15 s
TIMEOUT_S = 0.5
_CONFIG = (FIRMWARE / "core" / "irr_config.h").read_text()
SAMPLE_PERIOD_MS, STEP_MS = (int(re.search(rf"#define IRR_{name}\s+(\d+)", _CONFIG)[1])
                             for name in ("SAMPLE_PERIOD_MS", "STEP_MS"))


def count(step, sensor):
    """The host build's synthetic reading (firmware/README.md, "Host build")."""
    return 400 + 97 * np.asarray(sensor) + 7 * (np.asarray(step) + 35)


def counts_for(steps) -> np.ndarray:
    steps = np.asarray(steps)
    return count(steps[:, None], np.arange(12)[None, :])


@pytest.fixture(scope="session")
def host_binary() -> Path:
    if shutil.which("make") is None or shutil.which("cc") is None:
        pytest.skip("make and a C compiler are needed to build firmware/ (bash .ci/system-deps installs them)")
    subprocess.run(["make", "-s", "-C", str(FIRMWARE), "host"], check=True,
                   capture_output=True, timeout=120)
    return HOST


@pytest.fixture
def device(host_binary, tmp_path):
    """Start irring-host on a pty; returns a function giving its link path."""
    procs: list[subprocess.Popen] = []

    def start(speed: float = SPEED) -> str:
        link = tmp_path / f"ttyIRR{len(procs)}"
        proc = subprocess.Popen([str(host_binary), "--link", str(link), "--speed", str(speed)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        procs.append(proc)
        line = proc.stdout.readline().decode()
        assert "serving IRR v2 on /dev/pts/" in line and link.is_symlink(), line
        return str(link)

    yield start
    for proc in procs:
        proc.terminate()
        proc.wait(timeout=5)
        assert proc.returncode == 0, proc.stderr.read().decode()


class Raw:
    """A raw serial conversation with the device: send bytes, collect decoded sentences."""

    def __init__(self, link: str):
        self.port = serial.serial_for_url(link, baudrate=115200, timeout=0.02)
        self.decoder = p.Decoder()
        self.lines: list[bytes] = []

    def send(self, data: bytes) -> None:
        self.port.write(data)

    def read_until(self, done, wait_s: float = 2.0) -> list:
        """Sentences until done(list of messages) is true (or wait_s passes)."""
        got: list = []
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and not done(got):
            chunk = self.port.read(4096)
            self.lines += re.findall(rb"\$[^$]*?\r\n", chunk)
            got += self.decoder.feed(chunk)
        return got

    def ask(self, data: bytes, n: int = 1, wait_s: float = 1.0) -> list:
        self.send(data)
        return self.read_until(lambda got: len(got) >= n, wait_s)

    def quiet(self, wait_s: float = 0.15) -> list:
        """Whatever else arrives within wait_s (expected: nothing)."""
        return self.read_until(lambda got: False, wait_s)

    def close(self) -> None:
        self.port.close()


@pytest.fixture
def raw(device):
    conn = Raw(device())
    yield conn
    conn.close()


# --------------------------------------------------------------------------- SerialRing


def test_handshake_reports_the_papers_ring(device):
    with SerialRing(device(), timeout_s=TIMEOUT_S) as ring:
        info = ring.info
        assert info == p.info_for_ring(PAPER_RING, 12, info.firmware)
        assert (info.nsensors, info.adc_bits, info.step_mdeg, info.gear_num, info.gear_den,
                info.min_step, info.max_step) == (12, 12, 1800, 3, 5, -35, 35)
        assert info.firmware.startswith("irring-fw-")
        assert ring.ring == PAPER_RING


def test_full_sweep_has_every_step_with_the_documented_counts_and_honest_timing(device):
    settle_ms, samples = 7, 3
    with SerialRing(device(), timeout_s=TIMEOUT_S) as ring:
        sweep = ring.sweep(samples=samples, settle_s=settle_ms / 1000)
        assert np.array_equal(sweep.steps, np.arange(-35, 36))
        assert sweep.missing_steps == ()
        assert np.array_equal(sweep.counts, counts_for(sweep.steps))
        report = ring.last_report
        assert report.complete and report.link["lost_scans"] == 0
        assert report.link["seq_gaps"] == 0 and report.link["malformed"] == 0
        # device clock: each step costs at least a motor step, the settle and the samples
        # (a busy machine only adds to that)
        dt_ms = np.diff(sweep.timestamps_s) * 1000
        floor = STEP_MS + settle_ms + samples * SAMPLE_PERIOD_MS
        assert dt_ms.min() >= floor - 1e-6


def test_a_step_costs_no_more_than_its_settle_and_samples(device):
    """The device wastes no time: the median step takes less than twice its floor. On a
    device clock at wall time (speed 1), not the ×20 one: a wake-up late by a few wall ms
    under load would read as 20× that in device ms (the bound flaked), here it needs a
    lag of a whole floor (126 ms) per step."""
    settle_ms, samples = 7, 3
    with SerialRing(device(speed=1), timeout_s=TIMEOUT_S) as ring:
        sweep = ring.sweep(steps=np.arange(-4, 5), samples=samples, settle_s=settle_ms / 1000)
    assert np.array_equal(sweep.counts, counts_for(np.arange(-4, 5)))
    dt_ms = np.diff(sweep.timestamps_s) * 1000
    floor = STEP_MS + settle_ms + samples * SAMPLE_PERIOD_MS
    assert dt_ms.min() >= floor - 1e-6
    assert np.median(dt_ms) < 2 * floor


@pytest.mark.parametrize("samples", [1, 2, 4])
def test_averaging_undoes_the_per_sample_dither(device, samples):
    # sample j reads count + (0, -1, +1, -1, …)[j]: only a true average returns count
    with SerialRing(device(), timeout_s=TIMEOUT_S) as ring:
        sweep = ring.sweep(steps=[4, 5, 6], samples=samples)
        assert np.array_equal(sweep.counts, counts_for([4, 5, 6]))


def test_sub_ranges_in_both_directions_and_scattered_steps(device):
    with SerialRing(device(), timeout_s=TIMEOUT_S) as ring:
        down = ring.sweep(steps=np.arange(12, -5, -1))
        assert np.array_equal(down.steps, np.arange(12, -5, -1))
        assert np.array_equal(down.counts, counts_for(down.steps))
        assert np.all(np.diff(down.timestamps_s) > 0)  # read in the order asked
        up = ring.sweep(steps=np.arange(-30, -21))
        assert np.array_equal(up.counts, counts_for(np.arange(-30, -21)))
        scattered = [33, -17, 2, 3, 35]  # three IRSWP: 33; -17; 2…3; 35
        got = ring.sweep(steps=scattered)
        assert list(got.steps) == scattered and got.missing_steps == ()
        assert np.array_equal(got.counts, counts_for(scattered))


def test_goto_moves_the_motor_that_the_readings_come_from(device):
    with SerialRing(device(), timeout_s=TIMEOUT_S) as ring:
        assert ring.goto(-23) == -23
        assert ring.goto(31) == 31
        # the host HAL's readings follow its motor counter: a sweep at 31 reads step 31
        one = ring.sweep(steps=[31])
        assert np.array_equal(one.counts, counts_for([31]))


def test_stop_mid_sweep_ends_it_with_the_last_seq_sent(device):
    # the device clock at wall time: 141 ms a step, so "stopped within 10 steps" leaves a
    # second for the IRSTP to get through on a loaded machine (at ×20 it was 50 ms)
    raw = Raw(device(speed=1))
    try:
        _stop_mid_sweep(raw)
    finally:
        raw.close()


def _stop_mid_sweep(raw):
    raw.send(p.encode(p.SweepCommand(-35, 35, 1, 100)))  # 71 × 141 ms device time
    first = raw.read_until(lambda got: len(got) >= 3)
    assert len(first) >= 3 and all(isinstance(m, p.Scan) for m in first)
    raw.send(p.encode(p.Stop()))
    rest = raw.read_until(lambda got: any(isinstance(m, p.Done) for m in got))
    scans = first + [m for m in rest if isinstance(m, p.Scan)]
    done = [m for m in rest if isinstance(m, p.Done)]
    assert len(done) == 1 and done[0].seq == scans[-1].seq
    assert [s.seq for s in scans] == list(range(len(scans)))
    assert [s.step for s in scans] == list(range(-35, -35 + len(scans)))
    assert len(scans) < 10
    assert raw.quiet(0.5) == []  # stopped: no further IRSCN (three steps' time)
    # idle again: a new command is accepted, and seq carries on where it stopped
    answer = raw.ask(p.encode(p.SweepCommand(0, 1, 1, 0)), n=3, wait_s=3.0)
    assert [m.seq for m in answer[:2]] == [scans[-1].seq + 1, scans[-1].seq + 2]
    assert answer[2] == p.Done(scans[-1].seq + 2)


def test_stop_when_idle_reports_none_sent_and_serial_ring_stop_works(device):
    conn = Raw(device())
    assert conn.ask(p.encode(p.Stop())) == [p.Done(-1)]
    conn.close()
    with SerialRing(device(), timeout_s=TIMEOUT_S) as ring:
        ring.sweep(steps=[0, 1])
        assert ring.stop() == 1


# --------------------------------------------------------------------------- every IRERR


def line(body: str, version: int = 2) -> bytes:
    return p.frame(body.encode(), version)


def answers(stream: bytes) -> list[tuple[int, p.AnyMessage]]:
    """Each sentence a device sent, with the protocol version it was framed in."""
    out = []
    for raw in re.findall(rb"\$[^$]*?\r\n", stream):
        version = 1 if re.search(rb"\*[0-9A-F]{2}\r\n$", raw) else 2
        out.append((version, p.decode(raw, version=version)))
    return out


BAD = {
    1: [b"$IRHLO*26D1\r\n",                    # wrong CRC
        b"$IRGTO,7*d85b\r\n",                   # lower-case CRC (D85B is right)
        b"$IRGTO,7*D85\r\n", b"$IRGTO,7*D85B0\r\n",   # 3 and 5 digits
        line("IRHLO")[:-2] + b"\n",            # no \r
        line("IRGTO,5").replace(b"*", b""),     # no `*`
        line("IRGTO,x"), line("IRGTO,1.5"), line("IRGTO,+3"), line("IRGTO,-"),
        line("IRGTO,"), line("IRGTO"), line("IRHLO,1"), line("IRSWP,-3,,1,0"),
        line("IRSWP,1,2,3"), line("IRSWP,1,2,3,4,5"), line("IRhlo"), line("XYHLO"),
        line("IRHLOX"), line("IRGT\tO,1"), line("IRSWP,0,x,0,0"),
        # device sentences are checked like any other before they are refused
        line("IRSCN,0,1,2"), line("IRERR"), line("IRERR,1,a,b"), line("IRPOS,x")],
    2: [line("IRXYZ"), line("IRSCN,0,1,2,3"), line("IRPOS,3"), line("IRDON,-1"),
        line("IRSCN,65535,-2147483648,4294967295,0,4294967295"), line("IRERR,99"),
        line("IRINF,1,12,12,1800,3,5,-35,35,other")],
    3: [line("IRSWP,0,1,0,0"), line("IRSWP,0,1,65,0"), line("IRSWP,0,1,1,-1"),
        line("IRGTO,2147483648"), line("IRGTO,-2147483649"),
        line("IRGTO,99999999999999999999"), line("IRSWP,0,0,0,x"),
        line("IRDON,65536"), line("IRSCN,0,1,-2,3"), line("IRERR,0,x"),
        line("IRINF,1,12,12,1800,3,5,35,-35,fw")],  # min_step > max_step
    4: [line("IRGTO,36"), line("IRGTO,-36"), line("IRSWP,-36,0,1,0"), line("IRSWP,0,36,1,0"),
        line("IRGTO,-2147483648"), line("IRSWP,2147483647,0,64,2147483647")],
}


def reference_codes(data: bytes, framing: bool = False) -> list:
    """The IRERR codes the Python reference device (irring/hardware/emulator.py) would
    answer a byte stream with; with ``framing``, (version, code) pairs."""
    codes = []
    for item in p.Decoder().feed(data):
        if isinstance(item, p.ProtocolError) and item.fault is p.Fault.OTHER_VERSION:
            try:   # answered in v1 framing: IRHLO with IRINF, the rest with IRERR
                msg = p.decode(item.raw, version=1)
            except p.ProtocolError as exc:
                codes.append((1, exc.fault.device_error_code))
            else:
                if not isinstance(msg, p.Hello):
                    codes.append((1, 2 if msg.TYPE not in p.HOST_TYPES else 1))
        elif isinstance(item, p.ProtocolError):
            codes.append((2, item.fault.device_error_code))
        elif item.TYPE not in p.HOST_TYPES:
            codes.append((2, p.ERR_UNKNOWN_TYPE))
        elif isinstance(item, (p.GoTo, p.SweepCommand)):
            steps = [item.step] if isinstance(item, p.GoTo) else [item.from_step, item.to_step]
            if any(not -35 <= s <= 35 for s in steps):
                codes.append((2, p.ERR_STEP_RANGE))
    return codes if framing else [c for _, c in codes]


@pytest.mark.parametrize("code", sorted(BAD))
def test_each_bad_command_gets_its_irerr_code_like_the_reference(raw, code):
    for bad in BAD[code]:
        assert reference_codes(bad) == [code], bad  # the Python reference agrees
        got = raw.ask(bad)
        assert got == [p.ErrorReply(code, p.ERROR_TEXT[code])], bad
    assert raw.quiet() == []
    assert raw.ask(p.encode(p.GoTo(-1))) == [p.Position(-1)]  # nothing stuck


_TOKENS = st.sampled_from(["0", "-1", "35", "-36", "64", "65", "2147483648", "", "x", "1.5",
                           "+3", "-", "007", "-0", "99999999999"])
_TYPES = st.sampled_from(["IRHLO", "IRSTP", "IRGTO", "IRSWP", "IRINF", "IRSCN", "IRDON",
                          "IRPOS", "IRERR", "IRXYZ", "irgto", "IRGT", "IRGTOO", "XRGTO", ""])


@st.composite
def _sentence(draw) -> bytes:
    """Mostly well-framed sentences with plausible and implausible fields, sometimes broken."""
    body = ",".join([draw(_TYPES)] + draw(st.lists(_TOKENS, max_size=10))).encode()
    if draw(st.booleans()):
        body = body.replace(b",", draw(st.sampled_from([b",", b", ", b"\t", b"*", b"$"])), 1)
    cs, v1 = p.checksum(body), p.checksum(body, version=1)   # v1: an old host's sentences
    cs = draw(st.sampled_from([cs, cs, cs.lower(), b"0000", cs[:3], b"", v1, v1.lower(), b"00"]))
    end = draw(st.sampled_from([b"\r\n", b"\r\n", b"\n", b""]))
    noise = draw(st.binary(max_size=3).filter(lambda b: b"$" not in b))
    return noise + b"$" + body + b"*" + cs + end


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_sentence(), min_size=1, max_size=6))
def test_c_parser_rejects_exactly_what_the_python_reference_rejects(host_binary, sentences):
    stream = b"".join(sentences) + b"\r\n"
    # no motion command that would be accepted: the device never gets busy here
    assume(not any(isinstance(m, (p.GoTo, p.SweepCommand)) and
                   all(-35 <= s <= 35 for s in ([m.step] if isinstance(m, p.GoTo)
                                                else [m.from_step, m.to_step]))
                   for m in p.Decoder().feed(stream)))
    run = subprocess.run([str(host_binary), "--stdio"], input=stream, capture_output=True,
                         timeout=10)
    got = [(v, m.code) for v, m in answers(run.stdout) if isinstance(m, p.ErrorReply)]
    assert got == reference_codes(stream, framing=True)


def test_busy_while_sweeping_then_accepted_after(raw):
    raw.send(p.encode(p.SweepCommand(-35, 35, 1, 100)))
    assert isinstance(raw.read_until(lambda got: got)[0], p.Scan)
    got = raw.ask(p.encode(p.GoTo(3)) + p.encode(p.SweepCommand(0, 1, 1, 0)) +
                  p.encode(p.Hello()), n=3)
    got = [m for m in got if not isinstance(m, p.Scan)]
    assert got[:2] == [p.ErrorReply(5, "busy")] * 2
    assert isinstance(got[2], p.Info)  # IRHLO is answered mid-sweep
    raw.send(p.encode(p.Stop()))
    raw.read_until(lambda got: any(isinstance(m, p.Done) for m in got))
    assert raw.ask(p.encode(p.GoTo(3))) == [p.Position(3)]


def test_garbage_and_over_long_lines(raw):
    rng = np.random.default_rng(16)
    noise = bytes(rng.integers(0, 256, 3000, dtype=np.uint8))
    # noise without `$` is ignored entirely: the next command is answered alone
    quiet_noise = noise.replace(b"$", b"")
    assert raw.ask(quiet_noise + p.encode(p.Hello()), n=1)[0].TYPE == "IRINF"
    assert raw.quiet() == []
    # noise with `$`: every fragment is answered exactly as the Python reference decides
    stream = noise + b"\r\n" + p.encode(p.GoTo(2))
    want = reference_codes(stream)
    assert want.count(1) > 3  # the seed does make fragments
    got = raw.ask(stream, n=len(want) + 1, wait_s=3.0)
    assert [m.code for m in got[:-1]] == want and got[-1] == p.Position(2)
    # length: 128 bytes from `$` to `\n` is allowed, 129 is not (and answered once)
    for n_zeros, ok in ((128 - len(line("IRGTO,5")), True), (129 - len(line("IRGTO,5")), False)):
        sentence = line("IRGTO," + "0" * n_zeros + "5")
        assert len(sentence) == (128 if ok else 129)
        assert raw.ask(sentence) == ([p.Position(5)] if ok else [p.ErrorReply(1, "bad sentence")])
    assert raw.ask(b"$IRGTO," + b"1" * 5000 + b"\r\n" + p.encode(p.Hello()), n=2)[:1] == \
        [p.ErrorReply(1, "bad sentence")]
    assert raw.quiet() == []


def test_checksum_vectors_of_the_protocol_document(raw):
    doc = (ROOT / "docs" / "protocol.md").read_text()
    example = doc.split("## Example", 1)[1]
    vectors = {who: [m.encode() for m in re.findall(rf"^{who}:\s+(\$.*?\*[0-9A-F]{{4}})", example, re.M)]
               for who in ("host", "device")}
    assert len(vectors["host"]) == 3 and len(vectors["device"]) == 5
    for v in vectors["device"]:
        # a device sentence with a right checksum is a well-formed non-command: IRERR 2;
        # the same with the checksum's last digit changed is a bad sentence: IRERR 1
        assert raw.ask(v + b"\r\n") == [p.ErrorReply(2, "unknown type")], v
        wrong = v[:-1] + (b"0" if v[-1:] != b"0" else b"1")
        assert raw.ask(wrong + b"\r\n") == [p.ErrorReply(1, "bad sentence")], wrong
    hello, sweep, goto = vectors["host"]
    assert raw.ask(hello + b"\r\n")[0].TYPE == "IRINF"
    got = raw.ask(sweep + b"\r\n", n=72, wait_s=5.0)  # $IRSWP,-35,35,1,40
    assert [m.step for m in got[:-1]] == list(range(-35, 36)) and got[-1] == p.Done(70)
    # the device's own answer to `$IRGTO,99*86A9` is the document's line, byte for byte
    raw.lines.clear()
    assert raw.ask(goto + b"\r\n") == [p.ErrorReply(4, "step out of range")]
    assert raw.lines == [vectors["device"][-1] + b"\r\n"]


def test_the_c_crc_is_the_documents_and_pythons(host_binary):
    """firmware/core/irr_proto.c's CRC (the host build's C; the AVR's avr-libc
    _crc_ccitt_update is checked through every sentence of the simavr test below)."""
    def c_crc(text: str) -> str:
        return subprocess.run([str(host_binary), "--crc", text], capture_output=True,
                              text=True, check=True).stdout.strip()

    assert c_crc("123456789") == "906E" == f"{p.CRC16_CHECK:04X}"
    rng = np.random.default_rng(5)
    for n in (1, 2, 30, 120):
        text = "".join(chr(c) for c in rng.integers(0x21, 0x7F, n))
        assert c_crc(text) == f"{p.crc16(text.encode()):04X}", text


def test_an_old_hosts_v1_sentences_are_answered_in_v1_and_never_obeyed(raw):
    """A host that speaks only v1 learns from the IRINF it can read that this is a v2 device
    (proto 2); its commands are refused in a framing it reads."""
    raw.send(line("IRHLO", 1) + line("IRGTO,3", 1) + line("IRDON,1", 1) + b"$IRHLO*51\r\n")
    deadline = time.monotonic() + 2
    while time.monotonic() < deadline and len(raw.lines) < 4:
        raw.read_until(lambda got: False, 0.1)
    got = answers(b"".join(raw.lines))
    assert got == [(1, p.info_for_ring(PAPER_RING, 12, "irring-fw-2.0", version=2)),
                   (1, p.ErrorReply(1, "bad sentence")), (1, p.ErrorReply(2, "unknown type")),
                   (1, p.ErrorReply(1, "bad sentence"))]
    assert raw.ask(p.encode(p.GoTo(-1))) == [p.Position(-1)]   # the motor never went to 3


def test_device_sentences_decode_with_the_python_protocol(raw):
    raw.ask(p.encode(p.Hello()))
    raw.ask(p.encode(p.SweepCommand(35, 33, 64, 0)), n=4, wait_s=5.0)
    assert raw.lines and all(p.encode(p.decode(ln)) == ln for ln in raw.lines)


def test_stdio_mode_answers_and_finishes_the_sweep_before_exiting(host_binary):
    commands = p.encode(p.Hello()) + p.encode(p.SweepCommand(2, -1, 1, 0)) + line("IRGTO,9x")
    run = subprocess.run([str(host_binary), "--stdio", "--speed", "50"], input=commands,
                         capture_output=True, timeout=10)
    got = p.Decoder().feed(run.stdout)
    assert run.returncode == 0 and got[0].TYPE == "IRINF"
    # the bad IRGTO arrived during the sweep and is answered at once; the sweep still ends
    assert got[1] == p.ErrorReply(1, "bad sentence")
    assert [m.step for m in got[2:6]] == [2, 1, 0, -1] and got[6] == p.Done(3)


# --------------------------------------------------------------------------- irring drive


def test_irring_drive_maps_from_the_c_firmware(device, tmp_path, capsys):
    from irring.cli import main

    out = tmp_path / "drive"
    rc = main(["drive", "--port", device(), "--out", str(out), "--no-animation", "--no-wait",
               "--json", "--timeout", str(TIMEOUT_S), "--samples", "2"])
    assert rc == 0
    assert (out / "map.png").stat().st_size > 0 and (out / "map.pgm").exists()
    link = json.loads((out / "link.json").read_text())
    assert link["firmware"].startswith("irring-fw-")
    assert link["totals"]["scans"] == 71 and link["sweeps"][0]["missing_steps"] == []
    with np.load(out / "sweeps.npz") as z:
        counts = [z[k] for k in z.files if "counts" in k]
    assert counts and np.array_equal(counts[0], counts_for(np.arange(-35, 36)))


# --------------------------------------------------------------------------- the AVR image


def test_uart_divisor_for_115200_baud_at_16_mhz(host_binary):
    """UBRR and rate error (the same C macros the AVR build uses) against a Python oracle,
    and within the budget docs/protocol.md states."""
    make = (FIRMWARE / "Makefile").read_text()
    f_cpu = int(re.search(r"^F_CPU\s*\?=\s*(\d+)", make, re.M)[1])
    baud = int(re.search(r"^BAUD\s*\?=\s*(\d+)", make, re.M)[1])
    assert (f_cpu, baud) == (16_000_000, 115_200)
    tol = float(re.search(r"within ±([\d.]+) %", (ROOT / "docs" / "protocol.md").read_text())[1])

    def oracle(div):
        ubrr = round(f_cpu / (div * baud)) - 1
        return ubrr, f_cpu / (div * (ubrr + 1)) / baud - 1

    assert abs(oracle(16)[1]) * 100 > tol  # normal speed (UBRR 8) is −3.5 %: not good enough
    ubrr, err = oracle(8)
    assert (ubrr, round(err * 100, 2)) == (16, 2.12)
    report = subprocess.run([str(host_binary), "--baud", str(f_cpu), str(baud)],
                            capture_output=True, text=True)
    fields = dict(kv.split("=") for kv in report.stdout.split())
    assert report.returncode == 0 and fields["u2x"] == "1" and int(fields["ubrr"]) == ubrr
    assert int(fields["error_ppm"]) == int(err * 1e6) and abs(err) * 100 <= tol
    # a clock that cannot make the rate is refused
    bad = subprocess.run([str(host_binary), "--baud", "8000000", "115200"],
                         capture_output=True, text=True)
    assert bad.returncode == 1 and "ok=0" in bad.stdout


def avr_build(*args: str) -> subprocess.CompletedProcess:
    if shutil.which("avr-gcc") is None:
        pytest.skip("avr-gcc is not installed (bash .ci/system-deps installs gcc-avr avr-libc)")
    return subprocess.run(["make", "-s", "-C", str(FIRMWARE), "avr", *args],
                          capture_output=True, text=True, timeout=300)


def test_avr_image_fits_the_atmega328p_with_room_to_spare():
    build = avr_build()
    assert build.returncode == 0, build.stderr
    text = build.stdout
    flash = re.search(r"Program:\s+(\d+) bytes \(([\d.]+)% Full\)", text)
    ram = re.search(r"Data:\s+(\d+) bytes \(([\d.]+)% Full\)", text)
    assert flash and ram, text
    assert float(flash[2]) <= 75.0 and float(ram[2]) <= 60.0, text
    hex_file = FIRMWARE / "build" / "irring-atmega328p.hex"
    assert hex_file.exists() and hex_file.read_text().startswith(":")


def test_the_papers_atmega8535_image_fits_with_stack_to_spare():
    build = avr_build("MCU=atmega8535")
    assert build.returncode == 0, build.stderr
    flash = int(re.search(r"Program:\s+(\d+) bytes", build.stdout)[1])
    ram = int(re.search(r"Data:\s+(\d+) bytes", build.stdout)[1])
    assert flash <= 0.75 * 8192 and 512 - ram >= 160, build.stdout  # stack needs ~100 B


def test_flash_calls_avrdude_with_the_port_given():
    dry = subprocess.run(["make", "-n", "-C", str(FIRMWARE), "flash", "PORT=/dev/ttyACM7",
                          "PROGRAMMER=usbasp"], capture_output=True, text=True)
    cmd = [ln for ln in dry.stdout.splitlines() if ln.startswith("avrdude")]
    assert cmd == ["avrdude -p atmega328p -c usbasp -P /dev/ttyACM7 -b 115200 "
                   "-U flash:w:build/irring-atmega328p.hex:i"]


def test_avr_build_refuses_a_clock_outside_the_baud_budget():
    build = avr_build("F_CPU=8000000", "MCU=atmega328p", "BUILD=build/bad-clock")
    assert build.returncode != 0
    assert "baud" in build.stderr.lower()


# --------------------------------------------------------------------------- simavr


def test_the_avr_image_itself_in_simavr_answers_serial_ring(tmp_path):
    """The very ELF one flashes, run in simavr with six simulated MCP3202 on its SPI pins and
    a stepper counting its STEP/DIR edges (firmware/sim/irring_simavr.c): SerialRing gets
    the synthetic counts of the steps it asked for, so UART, SPI, chip selects and stepping
    all work as wired. simavr runs at roughly real speed, so the sweeps are short."""
    if shutil.which("avr-gcc") is None or not Path("/usr/include/simavr/sim_avr.h").exists():
        pytest.skip("needs gcc-avr and libsimavr-dev (bash .ci/system-deps installs them)")
    build = subprocess.run(["make", "-s", "-C", str(FIRMWARE), "sim"], capture_output=True,
                           text=True, timeout=300)
    assert build.returncode == 0, build.stderr
    link = tmp_path / "ttySIM"
    proc = subprocess.Popen([str(FIRMWARE / "build" / "irring-simavr"), "--link", str(link),
                             str(FIRMWARE / "build" / "irring-atmega328p.elf")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for text in iter(proc.stdout.readline, b""):
            if b"serving on" in text:
                break
        with SerialRing(str(link), timeout_s=2.0) as ring:
            assert ring.info == p.info_for_ring(PAPER_RING, 12, ring.info.firmware)
            up = ring.sweep(steps=[-3, -2, -1], samples=2)
            assert np.array_equal(up.counts, counts_for([-3, -2, -1]))
            assert ring.goto(6) == 6
            down = ring.sweep(steps=[5, 4])
            assert np.array_equal(down.counts, counts_for([5, 4]))
            # the AVR's Timer0 clock: a step, then each sample one GP2 period after the last
            assert np.diff(up.timestamps_s).min() * 1000 >= STEP_MS + 2 * SAMPLE_PERIOD_MS
            assert np.diff(down.timestamps_s).min() * 1000 >= STEP_MS + SAMPLE_PERIOD_MS
        conn = Raw(str(link))
        assert conn.ask(line("IRGTO,36"), wait_s=3.0) == [p.ErrorReply(4, "step out of range")]
        conn.close()
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    assert proc.returncode == 0, proc.stderr.read().decode()


@pytest.mark.parametrize("target, tool, advice", [
    ("avr", "AVRCC=irring-no-such-avr-gcc", "gcc-avr, avr-libc, binutils-avr"),
    ("flash", "AVRDUDE=irring-no-such-avrdude",
     "apt install avrdude or bash .ci/system-deps flash"),
])
def test_a_missing_build_tool_is_named_with_where_to_get_it(target, tool, advice, tmp_path):
    if shutil.which("make") is None:
        pytest.skip("make is needed (bash .ci/system-deps installs it)")
    if target == "flash" and shutil.which("avr-gcc") is None:
        pytest.skip("the AVR toolchain is needed to get as far as flashing")
    done = subprocess.run(["make", "-s", "-C", str(FIRMWARE), target, tool,
                           f"BUILD={tmp_path}"], capture_output=True, text=True)
    assert done.returncode != 0
    assert f"needs {tool.split('=')[1]}: " in done.stderr and advice in done.stderr


def test_system_deps_takes_flash_and_names_anything_else():
    """`bash .ci/system-deps flash` adds avrdude for a builder; a mistyped argument stops
    before apt is asked for anything."""
    done = subprocess.run(["bash", str(ROOT / ".ci" / "system-deps"), "flahs"],
                          capture_output=True, text=True)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr == "system-deps: unknown argument 'flahs'; allowed: flash (adds avrdude)\n"


def _compiler_without_headers(tmp_path) -> Path:
    """A compiler that runs but finds no header: gcc-avr without avr-libc, cc without
    libsimavr-dev."""
    fake = tmp_path / "bin" / "cc-without-headers"
    fake.parent.mkdir()
    fake.write_text("#!/bin/sh\necho 'fatal error: no such file' >&2\nexit 1\n")
    fake.chmod(0o755)
    return fake


@pytest.mark.parametrize("target, variable, header, package, advice", [
    ("avr", "AVRCC", "avr/io.h", "avr-libc",
     "Debian gcc-avr, avr-libc, binutils-avr (bash .ci/system-deps installs them)"),
    ("sim", "HOSTCC", "simavr/sim_avr.h", "libsimavr-dev",
     "Debian apt install libsimavr-dev (bash .ci/system-deps installs it)"),
])
def test_a_missing_library_is_named_with_where_to_get_it(target, variable, header, package,
                                                         advice, tmp_path):
    """A compiler without its library failed with the compiler's own "No such file": make
    names the package, as it does a missing tool."""
    if shutil.which("make") is None:
        pytest.skip("make is needed (bash .ci/system-deps installs it)")
    fake = _compiler_without_headers(tmp_path)
    done = subprocess.run(["make", "-s", "-C", str(FIRMWARE), target, f"{variable}={fake}",
                           f"BUILD={tmp_path}"], capture_output=True, text=True)
    shown = f"{fake} -mmcu=atmega328p" if target == "avr" else str(fake)
    built = tmp_path / ("irring-atmega328p.elf" if target == "avr" else "irring-simavr")
    assert done.returncode != 0
    assert done.stderr.splitlines()[0] == (f"make {built}: needs {package} (<{header}> not "
                                           f"found by {shown}): {advice}")


def test_system_deps_asks_for_avr_libc_when_only_the_compiler_is_there(tmp_path):
    """`command -v avr-gcc` passed a machine with gcc-avr but no avr-libc, and `make avr`
    then failed. Run where nothing but that compiler is on PATH and there is
    no apt-get, so the script lists what it would install and installs nothing."""
    fake = _compiler_without_headers(tmp_path)
    fake.rename(fake.parent / "avr-gcc")
    done = subprocess.run(["/bin/bash", str(ROOT / ".ci" / "system-deps")], capture_output=True,
                          text=True, env={"PATH": str(fake.parent)})
    assert done.returncode == 0, done.stderr
    wanted = done.stderr.removeprefix("irring: not a Debian system; install by hand: ").split()
    assert "avr-libc" in wanted and "gcc-avr" not in wanted and "binutils-avr" not in wanted
