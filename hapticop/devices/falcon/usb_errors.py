"""What can go wrong between the host and a Falcon on USB, in words a person can act on.

The driver (`usb_driver`) raises these; `explain` turns pyusb's errors (an errno under a
libusb message) into one of them naming the fix: a udev rule, another program holding the
device, the cable or the power. Nothing here needs pyusb.
"""

from __future__ import annotations

import errno

__all__ = ["FalconUsbError", "FalconLoaderError", "FalconDisconnected", "explain", "UDEV_RULE"]

UDEV_RULE = 'SUBSYSTEM=="usb", ATTRS{idVendor}=="0403", ATTRS{idProduct}=="cb48", MODE="0664", GROUP="plugdev"'
_UDEV_HINT = (f"give your user access with a udev rule, e.g. /etc/udev/rules.d/99-novint-falcon.rules "
              f"containing {UDEV_RULE} (then `udevadm control --reload` and replug, and be in group plugdev)")


class FalconUsbError(RuntimeError):
    """Something between the host and the Falcon failed; the message says what to do."""


class FalconLoaderError(FalconUsbError):
    """The boot loader did not take the firmware (a reopen and retry often helps, §2.6)."""


class FalconDisconnected(FalconUsbError):
    """The device went away (unplugged, powered off, reset)."""


def explain(error: Exception, doing: str) -> FalconUsbError:
    """A pyusb error as a FalconUsbError that names the cause a person can fix."""
    code = getattr(error, "errno", None)
    if code == errno.EACCES or code == errno.EPERM:
        return FalconUsbError(f"permission denied while {doing}: {_UDEV_HINT}")
    if code == errno.EBUSY:
        return FalconUsbError(f"the Falcon is busy while {doing}: another program (another hapticop, a "
                              "libnifalcon tool) has claimed it")
    if code == errno.ENODEV or code == errno.ENOENT:
        return FalconDisconnected(f"the Falcon disappeared while {doing}: unplugged or powered off?")
    return FalconUsbError(f"USB error while {doing}: {error}")
