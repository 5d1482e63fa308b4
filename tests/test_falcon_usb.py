"""The USB driver against the virtual Falcon: enumeration, the loader, the 1 kHz frame exchange.

The driver only talks pyusb; beneath it `VirtualUsbBackend` plays the FTDI chip, the boot
loader and the firmware, so everything here runs the code that would drive a real Falcon.
Time is a `VirtualClock`: no test sleeps, none asserts a wall-clock duration.
"""

from __future__ import annotations

import hashlib
import subprocess
import sys

import numpy as np
import pytest

from hapticop.devices.falcon import ftdi
from hapticop.devices.falcon.codec import MOTOR_LIMIT, Button, Flag, FrameCodec, Status, new_frame
from hapticop.devices.falcon.homing import Homing, HomingHand
from hapticop.devices.falcon.usb_driver import FalconUsb, connect, describe_falcons, find_falcons
from hapticop.devices.falcon.usb_errors import FalconDisconnected, FalconLoaderError, FalconUsbError
from hapticop.devices.falcon.virtual_clock import VirtualClock
from hapticop.devices.falcon.virtual_falcon import Phase, VirtualFalcon
from hapticop.devices.falcon.virtual_usb import VirtualUsbBackend

#: A stand-in image: a C2000 boot-table key and bytes that mean nothing (Novint's is never shipped).
IMAGE = b"\xaa\x08" + bytes((i * 7 + 3) & 0xFF for i in range(4000))


def falcon(**options) -> tuple[VirtualFalcon, VirtualUsbBackend]:
    device = VirtualFalcon(VirtualClock(), **options)
    return device, VirtualUsbBackend(device)


def running(**options) -> tuple[VirtualFalcon, FalconUsb]:
    device, backend = falcon(firmware_loaded=True, **options)
    return device, connect(None, backend=backend)


def exchange_n(driver: FalconUsb, n: int, flags: int = 0, motor=(0, 0, 0)) -> list[Status]:
    """n exchanges with one command; the statuses that came back, copied."""
    codec, command, status, got = FrameCodec(), new_frame(), Status(), []
    codec.encode_command(motor, flags, command)
    for _ in range(n):
        if driver.exchange(command, status):
            got.append(Status(status.encoders.copy(), status.homed.copy(), status.buttons, status.spare))
    return got


# ---------------------------------------------------------------- finding and opening
def test_describe_lists_a_falcon_with_its_strings_and_no_firmware():
    device, backend = falcon(serial="FT1234AB")
    [info] = describe_falcons(backend)
    assert (info.serial, info.product, info.bus, info.address) == ("FT1234AB", "FALCON HAPTIC", 1, 4)
    assert info.firmware_running is False and info.problem is None
    assert device.claimed_by is None  # released again


def test_describe_sees_running_firmware():
    _, backend = falcon(firmware_loaded=True)
    [info] = describe_falcons(backend)
    assert info.firmware_running is True


def test_permission_denied_names_the_udev_rule():
    _, backend = falcon(permission_denied=True)
    [info] = describe_falcons(backend)
    assert "permission denied" in info.problem and "udev" in info.problem and "cb48" in info.problem
    with pytest.raises(FalconUsbError, match="udev"):
        FalconUsb.open(0, backend)


def test_a_falcon_claimed_elsewhere_is_reported_busy():
    _, backend = falcon(busy=True)
    with pytest.raises(FalconUsbError, match="another program"):
        FalconUsb.open(0, backend)


def test_a_kernel_driver_is_detached():
    device, backend = falcon(kernel_driver=True, firmware_loaded=True)
    driver = connect(None, backend=backend)
    assert not device.kernel_driver and device.claimed_by is not None
    driver.close()


def test_index_chooses_among_several_falcons_and_bad_indexes_are_explained():
    first, second = VirtualFalcon(VirtualClock(), serial="A"), VirtualFalcon(VirtualClock(), serial="B", address=5)
    backend = VirtualUsbBackend(first, second)
    assert [d.serial for d in (first, second)] == ["A", "B"] and len(find_falcons(backend)) == 2
    driver = FalconUsb.open(1, backend)
    assert second.claimed_by is not None and first.claimed_by is None
    driver.close()
    with pytest.raises(FalconUsbError, match="index 2 asked for, but only 2 found"):
        FalconUsb.open(2, backend)
    with pytest.raises(FalconUsbError, match="no Falcon found on USB"):
        FalconUsb.open(0, VirtualUsbBackend())


def test_without_libusb_the_error_says_what_to_install():
    # pyusb caches a loaded libusb for the whole process, so ask in a fresh interpreter
    check = ("from hapticop.devices.falcon.usb_driver import system_backend\n"
             "from hapticop.devices.falcon.usb_errors import FalconUsbError\n"
             "try:\n    system_backend(find_library=lambda name: None)\n"
             "except FalconUsbError as error:\n    print(error)\n")
    done = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "libusb is not installed" in done.stdout


# ---------------------------------------------------------------- the loader
def test_connect_loads_the_firmware_with_libnifalcons_sequence():
    device, backend = falcon()
    log: list[str] = []
    driver = connect(IMAGE, backend=backend, log=log.append)
    assert device.phase is Phase.RUNNING and device.boots == 1 and device.uploaded == len(IMAGE)
    assert log == ["loading firmware, attempt 1 of 10"]
    R = ftdi.Request
    loader = [(R.RESET, 1, 0), (R.RESET, 2, 0), (R.LATENCY, 16, 0), (R.BAUD, 0x4138, 0), (R.LINE, 8, 0),
              (R.FLOW_CTRL, 0, 0), (R.MODEM_CTRL, 0x0200, 0), (R.MODEM_CTRL, 0x0100, 0),
              (R.MODEM_CTRL, 0x0101, 0), (R.MODEM_CTRL, 0x0100, 0), (R.BAUD, 0x0015, 0),
              (R.LATENCY, 1, 0), (R.BAUD, 0x0002, 0), (R.RESET, 1, 0), (R.RESET, 2, 0)]
    normal = loader[-4:]
    assert device.requests[:4] == normal  # normal mode first, to probe for running firmware
    start = device.requests.index((R.LATENCY, 16, 0)) - 2
    assert device.requests[start:] == loader
    assert device.latency_ms == 1 and device.baud == 1_500_000.0
    assert len(exchange_n(driver, 10)) == 10  # one reply per command (the probe's is in flight)
    driver.close()


def test_running_firmware_is_not_reloaded():
    device, backend = falcon(firmware_loaded=True)
    connect(IMAGE, backend=backend).close()
    assert device.boots == 1 and device.uploaded == 0
    assert all(r[0] != ftdi.Request.MODEM_CTRL for r in device.requests)  # no DTR pulse


def test_no_firmware_and_no_image_is_a_clear_error():
    _, backend = falcon()
    with pytest.raises(FalconUsbError, match="firmware is not running and no firmware image was given"):
        connect(None, backend=backend)


@pytest.mark.parametrize("options", [
    {"handshake_leading_zero": True},  # seen on macOS
    {"autobaud_reply": b"\x13A"},  # what the FTD2XX comments expect
    {"handshake_failures": 3},  # retried within one attempt
    {"packet_data_limit": 1},  # every reply split into one-byte packets
])
def test_loader_variants_are_accepted(options):
    device, backend = falcon(**options)
    connect(IMAGE, backend=backend).close()
    assert device.phase is Phase.RUNNING and device.boots == 1


def test_a_corrupted_echo_aborts_the_attempt_and_a_reopen_retries():
    device, backend = falcon(corrupt_echo_at=1000)
    log: list[str] = []
    driver = connect(IMAGE, backend=backend, log=log.append)
    assert device.boots == 1 and device.phase is Phase.RUNNING
    assert log[0] == "loading firmware, attempt 1 of 10"
    assert "attempt 1 failed: firmware upload: the echo differs from the image at byte 1000" in log[1]
    assert log[2] == "loading firmware, attempt 2 of 10"
    driver.close()


def test_a_silent_loader_fails_with_a_power_hint():
    _, backend = falcon(handshake_failures=10_000)
    with pytest.raises(FalconLoaderError, match="in 2 attempts.*power supply"):
        connect(IMAGE, backend=backend, attempts=2)


def test_an_image_too_short_to_boot_is_reported():
    _, backend = falcon()
    with pytest.raises(FalconLoaderError, match="uploaded but does not answer"):
        connect(IMAGE[:500], backend=backend, attempts=1)


def test_the_probe_fails_before_the_firmware_and_the_virtual_device_answers_nothing():
    device, backend = falcon()
    with FalconUsb.open(0, backend) as driver:
        driver.normal_mode()
        assert not driver.firmware_running(groups=2)
        assert driver.frames == 0 and driver.resends > 0
    assert device.phase is Phase.BOOT_ROM


# ---------------------------------------------------------------- frames
def test_frames_carry_encoders_buttons_leds_and_saturated_motors():
    device, driver = running()
    device.falcon.buttons = int(Button.CENTRE | Button.PLUS)
    flags = int(Flag.LED_BLUE | Flag.LED_GREEN)
    statuses = exchange_n(driver, 20, flags, motor=(40_000, -40_000, 123))
    assert len(statuses) == 20
    assert statuses[-1].buttons == Button.CENTRE | Button.PLUS
    assert device.falcon.leds == flags
    assert device.falcon.motor.tolist() == [MOTOR_LIMIT, -MOTOR_LIMIT, 123]  # saturated by the driver
    assert np.abs(statuses[-1].encoders).max() > 0  # the saturated motors moved the handle
    in_flight = FrameCodec().decode_status(device._reply.copy(), Status())  # the device's last reply
    status, command = Status(), new_frame()
    FrameCodec().encode_command((0, 0, 0), flags, command)
    assert driver.exchange(command, status)
    assert status.encoders.tolist() == in_flight.encoders.tolist() and status.buttons == in_flight.buttons
    assert driver.reader.rejected == 0 and driver.reader.discarded == 0


def test_the_driver_reads_64_byte_packets_at_a_1_ms_latency_timer():
    device, driver = running()
    exchange_n(driver, 200)
    assert device.latency_ms == 1
    assert len(driver._packet) == ftdi.PACKET_SIZE
    # one packet per exchange, and a frame in nearly every one: the loop runs at the timer's pace
    assert driver.frames >= 199 - driver.empty_reads and driver.empty_reads <= 1


@pytest.mark.parametrize("fault, lost_frames", [
    (lambda d: d.lose_bytes(1), 1),  # a lost byte: that frame only
    (lambda d: d.lose_bytes(5), 1),  # a truncated frame
    (lambda d: d.insert_bytes(b"<AB"), 0),  # a shifted stream: garbage ahead of a frame
    (lambda d: d.insert_bytes(b"x"), 0),  # one extra byte
    (lambda d: d.corrupt_byte(7), 1),  # a corrupted nibble
    (lambda d: d.corrupt_byte(15, 0x01), 1),  # a corrupted end marker
    (lambda d: d.corrupt_byte(0, 0x01), 1),  # a corrupted start marker
])
def test_the_stream_resynchronises_after_damaged_frames(fault, lost_frames):
    device, driver = running()
    before = exchange_n(driver, 10)
    fault(device)
    after = exchange_n(driver, 40)
    assert len(before) == 10
    # exactly the damaged reply is lost (the last reply is still in flight), and every frame
    # after it decodes: libnifalcon, stepping 16 bytes at a time, would lose all of them
    assert device.falcon.frames_out - driver.frames == lost_frames + 1
    assert driver.resends == lost_frames  # a lost reply is resent after `resend_after` empty reads
    assert len(after) == 40 - lost_frames * driver.resend_after
    assert driver.reader.rejected + driver.reader.discarded > 0


def test_frames_split_across_packets_are_reassembled():
    device, driver = running(packet_data_limit=5)
    got = exchange_n(driver, 100)
    assert len(got) >= 20 and driver.reader.rejected == 0 and driver.reader.discarded == 0 and driver.resends == 0


def test_a_mute_firmware_gets_resends_and_no_exception_then_recovers():
    device, driver = running()
    exchange_n(driver, 5)
    device.mute()
    assert len(exchange_n(driver, 50)) == 1  # the reply already on its way, then nothing
    assert driver.resends >= 4
    device.mute(False)
    assert len(exchange_n(driver, 20)) >= 9


def test_an_unplugged_falcon_raises_disconnected():
    device, driver = running()
    exchange_n(driver, 5)
    device.unplug()
    with pytest.raises(FalconDisconnected, match="unplugged or powered off"):
        exchange_n(driver, 2)
    assert find_falcons(VirtualUsbBackend(device)) == []
    driver.close()  # safe after an unplug


def test_homing_through_the_driver():
    clock = VirtualClock()
    device = VirtualFalcon(clock, firmware_loaded=True, hand=HomingHand())
    driver = connect(None, backend=VirtualUsbBackend(device))
    homing, codec, command, status = Homing(), FrameCodec(), new_frame(), Status()
    assert not device.falcon.homed.any()
    for _ in range(10_000):
        codec.encode_command((0, 0, 0), homing.command_flags(), command)
        if driver.exchange(command, status) and homing.update(status):
            break
    assert homing.homed and device.falcon.homed.all()
    codec.encode_command((0, 0, 0), homing.command_flags(), command)
    exchange_n(driver, 3, homing.command_flags())
    assert device.falcon.leds == Flag.LED_GREEN and device.falcon.flags & Flag.HOMING


def test_the_test_image_is_not_novints():
    from hapticop.devices.falcon.firmware import KNOWN_IMAGES

    assert hashlib.sha256(IMAGE).hexdigest() not in {image.sha256 for image in KNOWN_IMAGES}


# ---------------------------------------------------------------- the Falcon block on the USB driver
def _falcon_block(tmp_path, **params):
    import logging
    from types import SimpleNamespace

    from hapticop.blocks.falcon import Falcon, FalconParams
    from hapticop.runtime.clock import VirtualClock as RuntimeClock
    from hapticop.runtime.context import ActivityContext, InputPort, OutputPort

    clock = RuntimeClock()
    params = FalconParams(**params)
    inputs = SimpleNamespace(**{n: InputPort(n, p, clock.now_ns) for n, p in Falcon.inputs.items()})
    outputs = SimpleNamespace(**{n: OutputPort(n, p, clock.now_ns) for n, p in Falcon.outputs.items()})
    context = ActivityContext("falcon", params, inputs, outputs, {}, clock, logging.getLogger("test.falcon"),
                              np.random.default_rng(0), tmp_path)
    block = Falcon(context)
    block.create()
    return block, clock


def _until(step, clock, cycles: int) -> int:
    for cycle in range(cycles):
        if step():
            return cycle
        clock.advance_to(clock.now_ns() + 1_000_000)
        opening = getattr(step.__self__.link, "opening", None)
        if opening is not None:
            opening.join(30)  # the firmware load runs on its own thread
    raise AssertionError(f"{step.__name__} did not complete in {cycles} cycles")


def test_the_falcon_block_loads_homes_and_renders_forces_through_the_virtual_usb_device(tmp_path):
    image_path = tmp_path / "test-image.bin"
    image_path.write_bytes(IMAGE)
    block, clock = _falcon_block(tmp_path, driver="usb", usb_backend="virtual", firmware=str(image_path),
                                 firmware_sha256=hashlib.sha256(IMAGE).hexdigest())
    _until(block.configure_resources, clock, 100)
    assert block.virtual.boots == 1 and block.virtual.uploaded == len(IMAGE)
    _until(block.configure_capabilities, clock, 20_000)
    assert block.homing.homed and block.virtual.falcon.homed.all()
    block.inputs.force.value[:] = (0.0, 0.0, 2.0)
    for _ in range(50):
        block.compute()  # the runtime runs the schedule in between: then the write phase
        block.flush()
        clock.advance_to(clock.now_ns() + 1_000_000)
    assert block.flags["frames_ok"] and block.outputs.position.published >= 49
    assert np.abs(block.virtual.falcon.motor).max() > 0  # the force reaches the motors once homed
    block.clean()
    assert block.virtual.claimed_by is None and block.virtual.falcon.motor.tolist() == [0, 0, 0]


def test_the_falcon_block_refuses_an_unknown_firmware_image(tmp_path):
    from hapticop.devices.falcon.firmware import FirmwareError

    image_path = tmp_path / "image.bin"
    image_path.write_bytes(IMAGE)
    block, clock = _falcon_block(tmp_path, driver="usb", usb_backend="virtual", firmware=str(image_path))
    with pytest.raises(FirmwareError, match="image.bin is 4002 bytes; Novint's Falcon images are"):
        block.configure_resources()
