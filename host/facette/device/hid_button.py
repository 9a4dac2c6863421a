"""Optional USB HID start button (hidapi), for rigs whose button is not wired to the MCU.

Any HID device that sends an input report when pressed will do (a USB foot switch,
a one-key keypad): a report with a non-zero byte after the report id is "pressed",
an all-zero report is "released". ``facette scan --hid-button VID:PID`` waits for a
press, then starts the scan from the host (instead of the rig's own button).
"""
from __future__ import annotations

import time

__all__ = ["HidButton", "HidButtonError", "report_pressed", "parse_vid_pid"]


class HidButtonError(RuntimeError):
    """The HID button could not be opened or read."""


def report_pressed(report, report_id=True):
    """Whether an input report (sequence of ints) means "pressed"."""
    data = list(report)[1:] if report_id and len(report) > 1 else list(report)
    return any(int(b) for b in data)


def parse_vid_pid(text):
    """'16c0:05df' → (0x16c0, 0x05df)."""
    try:
        vid, pid = (int(v, 16) for v in text.split(":"))
    except ValueError:
        raise ValueError(f"HID button must be given as VID:PID in hex (e.g. 16c0:05df), got {text!r}") from None
    return vid, pid


class HidButton:
    """Open the HID device `vendor_id`:`product_id` (hex ids as from `lsusb`)."""

    def __init__(self, vendor_id, product_id, report_id=True):
        try:
            import hid
        except ImportError as exc:
            raise HidButtonError("a USB HID button needs hidapi: `pip install 'facette[hid]'`") from exc
        self.report_id = report_id
        self.dev = hid.device()
        try:
            self.dev.open(int(vendor_id), int(product_id))
        except (OSError, IOError) as exc:
            found = [f"{d['vendor_id']:04x}:{d['product_id']:04x} {d.get('product_string') or ''}".strip()
                     for d in hid.enumerate()]
            raise HidButtonError(f"cannot open HID device {vendor_id:04x}:{product_id:04x} ({exc}); "
                                 f"HID devices present: {found or 'none'} (on Linux, check the udev "
                                 "permissions of /dev/hidraw*)") from exc
        self.dev.set_nonblocking(True)

    def wait_press(self, timeout_s=None, poll_s=0.01):
        """Block until the button goes from released to pressed; False on timeout."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        was = False
        while deadline is None or time.monotonic() < deadline:
            report = self.dev.read(64)
            if report:
                now = report_pressed(report, self.report_id)
                if now and not was:
                    return True
                was = now
            else:
                time.sleep(poll_s)
        return False

    def close(self):
        self.dev.close()
