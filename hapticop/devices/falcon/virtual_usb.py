"""A Falcon at the far end of a virtual USB cable: a pyusb backend that plays the device.

The USB driver (`usb_driver`) runs unchanged against it: it enumerates, opens, sends FTDI
vendor requests and bulk transfers through pyusb, and this backend answers as the hardware
would (docs/devices/falcon.md §7). The backend only adapts pyusb's interface (handles,
descriptors, claims, transfers) to the devices it is given, FTDI chips of `virtual_ftdi`:
in practice `VirtualFalcon`s (`virtual_falcon`), the Falcon's DSP, loader and firmware behind
such a chip, living in the time of a clock from `virtual_clock`.
"""

from __future__ import annotations

import errno
from types import SimpleNamespace

import usb.backend

from hapticop.devices.falcon import ftdi
from hapticop.devices.falcon.virtual_ftdi import VirtualFtdi, usb_error

__all__ = ["VirtualUsbBackend"]


_CONFIG = SimpleNamespace(bLength=9, bDescriptorType=2, wTotalLength=32, bNumInterfaces=1, bConfigurationValue=1,
                          iConfiguration=0, bmAttributes=0x80, bMaxPower=45, extra_descriptors=[])
_INTERFACE = SimpleNamespace(bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0, bNumEndpoints=2,
                             bInterfaceClass=0xFF, bInterfaceSubClass=0xFF, bInterfaceProtocol=0xFF, iInterface=2,
                             extra_descriptors=[])
_ENDPOINTS = tuple(SimpleNamespace(bLength=7, bDescriptorType=5, bEndpointAddress=address, bmAttributes=2,
                                   wMaxPacketSize=ftdi.PACKET_SIZE, bInterval=0, bRefresh=0, bSynchAddress=0,
                                   extra_descriptors=[])
                   for address in (ftdi.EP_IN, ftdi.EP_OUT))
_GET_DESCRIPTOR = 6
_STRING = 3
_GET_LATENCY = 0x0A
_GET_MODEM_STATUS = 0x05


class _Handle:
    def __init__(self, device: VirtualFtdi) -> None:
        self.device = device
        self.open = True


class VirtualUsbBackend(usb.backend.IBackend):
    """pyusb's backend interface over a list of VirtualFalcons, or any `VirtualFtdi` (pass it as `backend=`)."""

    def __init__(self, *devices: VirtualFtdi) -> None:
        super().__init__()
        self.devices = list(devices)

    def _device(self, handle: _Handle) -> VirtualFtdi:
        if not handle.open:
            raise usb_error("Invalid parameter (closed handle)", -2, errno.EINVAL)
        handle.device.check()
        return handle.device

    # -- enumeration and descriptors
    def enumerate_devices(self):
        return [d for d in self.devices if d.plugged]

    def get_parent(self, dev):
        return None

    def get_device_descriptor(self, dev):
        return dev.device_descriptor

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError(config)
        return _CONFIG

    def get_interface_descriptor(self, dev, intf, alt, config):
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError(intf)
        return _INTERFACE

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        return _ENDPOINTS[ep]

    # -- handles and interfaces
    def open_device(self, dev):
        dev.check()
        if dev.permission_denied:
            raise usb_error("Access denied (insufficient permissions)", -3, errno.EACCES)
        return _Handle(dev)

    def close_device(self, handle):
        if handle.device.claimed_by is handle:
            handle.device.claimed_by = None
        handle.open = False

    def set_configuration(self, handle, config_value):
        self._device(handle)

    def get_configuration(self, handle):
        self._device(handle)
        return 1

    def set_interface_altsetting(self, handle, intf, altsetting):
        self._device(handle)

    def claim_interface(self, handle, intf):
        dev = self._device(handle)
        if dev.busy or (dev.claimed_by is not None and dev.claimed_by is not handle):
            raise usb_error("Resource busy", -6, errno.EBUSY)
        if dev.kernel_driver:
            raise usb_error("Resource busy (a kernel driver holds the interface)", -6, errno.EBUSY)
        dev.claimed_by = handle

    def release_interface(self, handle, intf):
        if handle.device.claimed_by is handle:
            handle.device.claimed_by = None

    def is_kernel_driver_active(self, handle, intf):
        return self._device(handle).kernel_driver

    def detach_kernel_driver(self, handle, intf):
        self._device(handle).kernel_driver = False

    def attach_kernel_driver(self, handle, intf):
        self._device(handle).kernel_driver = True

    def clear_halt(self, handle, ep):
        self._device(handle)

    def reset_device(self, handle):
        self._device(handle)

    # -- transfers
    def _claimed(self, handle) -> VirtualFtdi:
        dev = self._device(handle)
        if dev.claimed_by is not handle:
            raise usb_error("Resource busy (interface not claimed)", -6, errno.EBUSY)
        return dev

    def bulk_write(self, handle, ep, intf, data, timeout):
        if ep != ftdi.EP_OUT:
            raise usb_error("Pipe error", -9, errno.EPIPE)
        return self._claimed(handle).write(data.tobytes())

    def bulk_read(self, handle, ep, intf, buff, timeout):
        if ep != ftdi.EP_IN:
            raise usb_error("Pipe error", -9, errno.EPIPE)
        return self._claimed(handle).read(buff, timeout)

    def ctrl_transfer(self, handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        dev = self._device(handle)
        if bmRequestType == 0x80 and bRequest == _GET_DESCRIPTOR and wValue >> 8 == _STRING:
            index = wValue & 0xFF
            text = dev.strings(index)
            if index == 0:
                raw = bytes([4, _STRING, 0x09, 0x04])  # one language: en-US
            elif text is None:
                raise usb_error("Pipe error", -9, errno.EPIPE)
            else:
                encoded = text.encode("utf-16-le")
                raw = bytes([2 + len(encoded), _STRING]) + encoded
            n = min(len(raw), len(data))
            memoryview(data).cast("B")[:n] = raw[:n]
            return n
        if bmRequestType == ftdi.VENDOR_OUT:
            dev.control_out(bRequest, wValue, wIndex)
            return 0
        if bmRequestType == 0xC0 and bRequest == _GET_LATENCY and len(data) >= 1:
            data[0] = dev.latency_ms & 0xFF
            return 1
        if bmRequestType == 0xC0 and bRequest == _GET_MODEM_STATUS and len(data) >= 2:
            memoryview(data).cast("B")[0:2] = dev.status_bytes
            return 2
        raise usb_error("Pipe error (request not supported)", -9, errno.EPIPE)
