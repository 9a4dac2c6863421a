"""facette.bench._page: the benchmarks page written from the benchmarks' own printed output."""
import re

from facette.bench import _page
from facette.bench.diligent import PUBLISHED_OTHERS, print_table


def _printed_tables():
    """What `facette bench diligent` prints, through its own printer, for made-up results."""
    results = [(f"diligent_crop8/{name} 8-bit", 1000 + i, None,
                [("woodham1980", 10.0 + i, 9.0 + i, 0.5), ("rank_trimmed", 8.0 + i, 7.0 + i, 0.25)])
               for i, name in enumerate(("ball", "cat", "pot2", "buddha", "reading"))]

    def both():
        print_table(results, ["woodham1980", "rank_trimmed"], "all")
        print_table(results[:2], ["woodham1980", "rank_trimmed"], "12")
        return 0
    return _page.run_teed(both)


def test_tables_are_read_back_as_the_bench_printed_them():
    status, text, seconds = _printed_tables()
    assert status == 0 and seconds >= 0 and "DiLiGenT" in text
    tables = _page.diligent_tables(text)
    assert [t[0] for t in tables] == ["all lights", "12 lights near the rig's directions"]
    label, methods, rows = tables[0]
    assert methods == ["woodham1980", "rank_trimmed"]
    assert rows["diligent_crop8/cat 8-bit"] == [(11.0, 10.0, 0.5), (9.0, 8.0, 0.25)]
    assert rows["mean diligent_crop8"][1][0] == 10.0            # the mean of 8..12


def test_page_has_date_machine_published_figures_and_plot(tmp_path):
    outputs = {"diligent": _printed_tables(), "other": (1, "-- a section\nvalue 1.0 s\n", 2.0)}
    path = _page.write_page(outputs, tmp_path / "benchmarks.md")
    text = path.read_text()
    assert re.search(r"on \d{4}-\d\d-\d\d \d\d:\d\d UTC", text)
    assert "| cores |" in text and "| memory |" in text
    assert "| cat | 11.00 | 9.00 | 8.41 |" in text                # ours, then the published LS
    assert all(name in text for name in PUBLISHED_OTHERS)
    assert f"{PUBLISHED_OTHERS['Shi 2014 bi-polynomial'][1]:.2f}" in text
    assert (tmp_path / "img" / "bench" / "diligent-error-time.png").stat().st_size > 1000
    assert "**a section**" in text and "value 1.0 s" in text and "| [`other`](#other) | 1 | 2 s |" in text


def test_a_run_without_diligent_writes_no_table_and_no_plot(tmp_path):
    path = _page.write_page({"hdr": (0, "-- merge\n1.0 dB 2.0 s\n", 1.0)}, tmp_path / "b.md")
    assert "beside the published" not in path.read_text()
    assert not (tmp_path / "img").exists()
