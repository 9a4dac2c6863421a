"""`facette bench size` end to end on a tiny slab: both runs, their figures, their agreement."""
import re

from facette.bench import size


def test_tiny_slab_tiled_equals_untiled(tmp_path, capsys):
    assert size.main(["--sizes", "64x48", "--memory", "1GB", "--keep", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.strip().startswith("64x48"))
    figures = [float(x) for x in re.findall(r"-?\d+\.\d+|\b\d+\b", row.split("|", 1)[1])]
    gen_s, gen_gb, u_s, u_spm, u_gb, u_load, u_ps, t_s, t_spm, t_gb, tiles, t_stage, t_ps, err_u, err_t, worst, over = figures
    assert 0 < u_gb < 2 and 0 < t_gb < 2 and tiles == 1
    assert err_u == err_t and err_t < 5                     # the same normals, near the truth
    assert worst < 0.01 and over == 0                       # degrees, tiled against untiled
    assert (tmp_path / "untiled_64x48" / "normal.exr").is_file()


def test_sizes_by_name_or_width_and_height():
    assert size._size("12") == (4288, 2848)
    assert size._size("100") == (11648, 8736)
    assert size._size("640x480") == (640, 480)
