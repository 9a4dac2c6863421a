"""The camera of a real rig, from the options `facette scan` and `facette calibrate` share."""
import tempfile
from pathlib import Path


def real_rig_camera(args, download_dir=None):
    """A FolderWatchCamera (--camera-dir) or a GPhoto2Camera (--gphoto2, files into
    `download_dir`, a new temporary folder when None); exits with what to pass when neither
    was given."""
    if args.gphoto2:
        from facette.camera import GPhoto2Camera

        if download_dir is None:
            download_dir = Path(tempfile.mkdtemp(prefix="facette-camera-"))
        return GPhoto2Camera(download_dir=download_dir)
    if args.camera_dir:
        from facette.camera import FolderWatchCamera

        return FolderWatchCamera(args.camera_dir)
    raise SystemExit("a real rig needs a camera: --camera-dir FOLDER (tethering software writes there) "
                     "or --gphoto2")
