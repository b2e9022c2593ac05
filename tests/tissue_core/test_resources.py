"""What an option asks for is checked against the memory and the disk before it is made."""

import shutil

import pytest

import tissue_core.resources as resources
from tissue_core.errors import InputError
from tissue_core.resources import check_fits, format_size, free_disk


@pytest.mark.parametrize(
    ("n", "text"),
    [(0, "0 bytes"), (1023, "1023 bytes"), (1024, "1 KiB"), (1536, "1.5 KiB"),
     (80_000_000_000, "74.5 GiB"), (1023.9 * 2**20, "1024 MiB"), (2**40, "1 TiB")],
)  # fmt: skip
def test_sizes_read_as_numpy_names_them(n, text):
    assert format_size(n) == text


def test_memory_beyond_what_is_available_is_refused_naming_both(monkeypatch):
    monkeypatch.setattr(resources, "available_memory", lambda: 2 * 2**30)
    check_fits("--grid 9x9", memory=2 * 2**30)  # exactly what there is: fits
    with pytest.raises(InputError) as err:
        check_fits("--grid 900x900 (810000 points over 6 frames)", memory=3 * 2**30)
    assert str(err.value) == (
        "--grid 900x900 (810000 points over 6 frames) needs 3 GiB of memory; 2 GiB is "
        "available: ask for less"
    )
    with pytest.raises(InputError, match=r"available: use a coarser grid$"):
        check_fits("--grid 900x900", memory=3 * 2**30, remedy="use a coarser grid")


def test_the_disk_of_the_output_is_asked_even_before_the_output_exists(tmp_path, monkeypatch):
    asked = []

    def usage(folder):
        asked.append(folder)
        return shutil._ntuple_diskusage(100, 90, 10)

    monkeypatch.setattr(shutil, "disk_usage", usage)
    out = tmp_path / "new" / "deeper" / "run"
    assert free_disk(out) == 10 and asked == [tmp_path]
    check_fits("--size 64", disk=10, out=out)
    with pytest.raises(InputError, match=r"--size 800 writes 1 KiB; the disk of .*deeper has "
                       r"10 bytes free: use fewer frames"):  # fmt: skip
        check_fits("--size 800", disk=1024, out=out, remedy="use fewer frames")


def test_sizes_no_number_can_hold_are_refused():
    with pytest.raises(InputError, match="--frames 1e400 asks for more than any machine holds"):
        check_fits("--frames 1e400", memory=float("inf"))
