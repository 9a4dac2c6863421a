"""gphoto2 backend: what can run without a camera on this machine.

python-gphoto2's bundled libgphoto2 has the "Directory Browse" camera driver but
not the "disk:" port library it needs, so no virtual camera can be opened here;
with no USB camera, opening must fail with a clear message.
"""
import gphoto2 as gp   # in the dev extra, so `make test` always runs these
import pytest

from facette.camera.gphoto2 import CameraError, GPhoto2Camera


def test_libgphoto2_knows_the_cameras_we_expect():
    abilities = gp.CameraAbilitiesList()
    abilities.load()
    models = {abilities.get_abilities(i).model for i in range(abilities.count())}
    assert "Nikon DSC D300 (PTP mode)" in models or any("D300" in m for m in models)


def test_no_camera_gives_a_clear_error(tmp_path):
    with pytest.raises(CameraError, match="gphoto2 --auto-detect"):
        GPhoto2Camera(tmp_path / "dl")
