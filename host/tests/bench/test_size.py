"""`facette bench size` end to end on a tiny slab: both runs, their figures, their agreement."""
import re

from facette.bench import size


NUMBER = r"-?\d+\.\d+(?:e[+-]\d+)?|\b\d+\b"


def test_tiny_slab_tiled_equals_untiled(tmp_path, capsys):
    assert size.main(["--sizes", "64x48", "--memory", "1GB", "--keep", str(tmp_path), "--scan", "--no-flag"]) == 0
    out = capsys.readouterr().out
    no_flag = next(line for line in out.splitlines() if line.startswith("no flag 64x48: "))
    assert "li_alternating; memory: a budget of" in no_flag and "is read whole" in no_flag
    assert re.search(r"CPU s, .* \d+\.\d+° to the truth, li_alternating", no_flag)
    slab, scan = [line for line in out.splitlines() if line.strip().startswith("64x48")]
    figures = [float(x) for x in re.findall(NUMBER, slab.split("|", 1)[1])]
    gen_s, gen_gb, u_s, u_spm, u_gb, u_load, u_ps, t_s, t_spm, t_gb, tiles, t_stage, t_ps, err_u, err_t, worst, over, \
        m_s, m_cpu, m_spm, m_gb, m_bands, m_ps, m_deg, m_over, m_height = figures
    assert 0 < u_gb < 2 and 0 < t_gb < 2 and tiles == 1
    assert err_u == err_t and err_t < 5                     # the same normals, near the truth
    assert worst < 0.01 and over == 0                       # degrees, tiled against untiled
    assert (tmp_path / "untiled_64x48" / "normal.exr").is_file()
    # process --memory against untiled process: normals and heights
    assert 0 < m_cpu and 0 < m_gb < 2 and m_bands == 1 and m_deg < 0.01 and m_over == 0 and m_height <= 1e-3
    # the slab as a scan directory: untiled and --memory process agree
    s_gen, s_u, s_uspm, s_ugb, s_m, s_mspm, s_mgb, s_bands, s_deg, s_over, s_height, s_brdf = \
        [float(x) if x != "nan" else float("nan") for x in re.findall(NUMBER + "|nan", scan.split("|", 1)[1])]
    assert 0 < s_mgb < 2 and s_bands == 1 and s_deg < 0.01 and s_over == 0 and s_height <= 1e-3


def test_sizes_by_name_or_width_and_height():
    assert size._size("12") == (4288, 2848)
    assert size._size("100") == (11648, 8736)
    assert size._size("640x480") == (640, 480)


def test_kill_worker_in_seconds_or_a_share_of_the_memory_run():
    assert size._kill_seconds("12", {"mem_s": 300.0}) == 12.0
    assert size._kill_seconds("33%", {"mem_s": 300.0}) == 99.0
    assert size._kill_seconds("0", {}) == 0.0


def test_the_no_flag_run_alone_of_a_scan_directory_written_when_missing(tmp_path, capsys):
    assert size.main(["--sizes", "40x32", "--keep", str(tmp_path), "--scan", "--only-no-flag"]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "scan_40x32" / "scan.json").is_file() and not (tmp_path / "memory_40x32").exists()
    line, = [line for line in out.splitlines() if line.startswith("no flag")]
    assert line.startswith("no flag scan 40x32: ") and "is read whole" in line, line
    err = float(re.search(r"(\d+\.\d+)° to the truth, li_alternating", line).group(1))
    assert err < 5, line
