"""cli relight: a .ptm or .rti file rendered under a light, as the viewers show it."""
import numpy as np

from facette.cli.main import main
from facette.io.png import read_png
from facette.io.ptm import write_ptm_lrgb
from facette.io.rti import write_hsh_rti


def test_relight_writes_the_picture_of_a_ptm_and_an_rti(tmp_path, capsys):
    h, w = 6, 10
    coeffs = np.zeros((h, w, 6))
    coeffs[..., 3] = 0.5                         # brighter towards +x (lu)
    coeffs[..., 5] = 0.5
    write_ptm_lrgb(tmp_path / "a.ptm", coeffs, np.ones((h, w, 3)))
    assert main(["relight", str(tmp_path / "a.ptm"), "--light", "0,30", "-o", str(tmp_path / "a.png")]) == 0
    right = read_png(tmp_path / "a.png")
    main(["relight", str(tmp_path / "a.ptm"), "--light", "180,30", "-o", str(tmp_path / "b.png")])
    left = read_png(tmp_path / "b.png")
    assert right.shape == (h, w, 3) and right.mean() > left.mean() + 50     # 0.5 ± 0.43 of 255
    hsh = np.zeros((h, w, 3, 4))
    hsh[..., 0] = 0.5 * np.sqrt(2 * np.pi)       # the constant term: 0.5 everywhere
    write_hsh_rti(tmp_path / "c.rti", hsh, ["encoding: srgb"])
    assert main(["relight", str(tmp_path / "c.rti"), "-o", str(tmp_path / "c.png")]) == 0
    assert abs(int(read_png(tmp_path / "c.png").mean()) - 128) <= 1
    assert "HSH 4 terms" in capsys.readouterr().out


def test_relight_refuses_what_it_cannot_read(tmp_path, capsys):
    (tmp_path / "x.rti").write_bytes(b"hello")
    assert main(["relight", str(tmp_path / "x.rti")]) == 2
    assert main(["relight", str(tmp_path / "none.ptm")]) == 2
    assert main(["relight", str(tmp_path / "x.rti"), "--light", "up"]) == 2
    assert "neither a PTM nor an HSH" in capsys.readouterr().err
