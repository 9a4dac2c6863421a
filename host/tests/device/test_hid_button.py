"""USB HID start button: report decoding and the error when hidapi or the device is missing."""
import importlib.util

import pytest

from facette.device.hid_button import HidButton, HidButtonError, parse_vid_pid, report_pressed


def test_reports_decode_to_pressed_and_released():
    assert report_pressed([1, 0, 4, 0]) and not report_pressed([1, 0, 0, 0])
    assert report_pressed([0, 1], report_id=False) and not report_pressed([0, 0], report_id=False)


def test_vid_pid_parsing():
    assert parse_vid_pid("16c0:05DF") == (0x16C0, 0x05DF)
    with pytest.raises(ValueError, match="VID:PID in hex"):
        parse_vid_pid("foot switch")


def test_opening_without_the_device_says_what_to_do():
    expected = "cannot open HID device" if importlib.util.find_spec("hid") else "needs hidapi"
    with pytest.raises(HidButtonError, match=expected):
        HidButton(0x16C0, 0x05DF)
