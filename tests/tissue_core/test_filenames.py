"""Names that are not UTF-8: read, written, and shown as valid UTF-8 text everywhere."""

import io
import os
import subprocess
import sys

import pytest

from tests.badinput import REPO
from tests.filenames import latin1, shown, strict_json
from tissue_core.cli import one_line
from tissue_core.filenames import exact_name, is_utf8, readable, utf8_alias, utf8_output
from tissue_core.html import HtmlReport, input_records
from tissue_core.jsonio import write_json
from tissue_core.outputs import (
    LEDGER,
    MARKER,
    atomic_dir,
    atomic_file,
    check_writable,
    foreign_content,
    recorded_command,
)
from tissue_core.progress import Progress

VIDEO = latin1("vidéo.avi")


def test_a_name_that_is_not_utf8_reads_with_its_bytes_escaped():
    assert VIDEO == "vid\udce9o.avi" and not is_utf8(VIDEO)
    assert readable(VIDEO) == "vid\\xe9o.avi" == shown(VIDEO)
    assert readable(os.fsencode(VIDEO)) == "vid\\xe9o.avi"
    assert readable("vidéo.avi") == "vidéo.avi" and is_utf8("vidéo.avi")
    assert readable("a\ud800b") == "a\\ud800b"  # a lone surrogate of another origin
    assert exact_name(VIDEO) == os.fsencode(VIDEO).hex() and exact_name("vidéo.avi") is None
    assert bytes.fromhex(exact_name(VIDEO)) == b"vid\xe9o.avi"


def test_an_alias_names_the_same_file_and_folder_in_utf8(tmp_path):
    folder = tmp_path / latin1("Messdatén")
    folder.mkdir()
    video = folder / VIDEO
    video.write_bytes(b"frames")
    with utf8_alias(video) as alias, utf8_alias(folder) as alias_folder:
        assert is_utf8(alias) and alias.suffix == ".avi"
        assert str(alias).encode("utf-8") and alias.read_bytes() == b"frames"
        assert [p.name for p in alias_folder.iterdir()] == [VIDEO]
        made = [alias.parent, alias_folder.parent]
    assert not any(p.exists() for p in made)  # the private links are gone
    assert video.read_bytes() == b"frames"
    plain = tmp_path / "plain.avi"
    with utf8_alias(plain) as same:
        assert same == plain


def test_an_alias_keeps_no_suffix_that_is_not_utf8(tmp_path):
    odd = tmp_path / latin1("frames.tïf")
    odd.write_bytes(b"x")
    with utf8_alias(odd) as alias:
        assert alias.suffix == "" and alias.read_bytes() == b"x"


def test_json_results_are_valid_utf8_for_strict_readers(tmp_path):
    path = tmp_path / "summary.json"
    write_json(path, {"input": tmp_path / VIDEO, latin1("clé"): [latin1("é")], "µm": "µm"})
    data = strict_json(path)
    assert data["input"] == shown(tmp_path / VIDEO)
    assert data["cl\\xe9"] == ["\\xe9"] and data["µm"] == "µm"


def test_html_reports_show_such_names_and_are_valid_utf8(tmp_path):
    video = tmp_path / VIDEO
    video.write_bytes(b"frames")
    doc = HtmlReport(f"Run of {VIDEO}")
    doc.inputs(input_records([video]))
    doc.key_values({"source": {"path": str(video)}})
    doc.provenance({"command": ["strain2d", "analyze", str(video)]})
    doc.write(tmp_path / "report.html")
    text = (tmp_path / "report.html").read_bytes().decode("utf-8")
    assert "vid\\xe9o.avi" in text and "\\udc" not in text


def test_messages_show_such_names_readably():
    assert one_line(f"cannot read {VIDEO}") == "cannot read vid\\xe9o.avi"
    # Python's own OSError text quotes the name with repr
    error = FileNotFoundError(2, "No such file or directory", VIDEO)
    assert one_line(error) == "[Errno 2] No such file or directory: 'vid\\xe9o.avi'"
    stream = io.StringIO()
    progress = Progress(stream=stream)
    progress.say(f"{VIDEO}: 5 frames")
    with progress.task(f"reading {VIDEO}") as task:
        task(1, 1)
    assert "\\udc" not in stream.getvalue() and stream.getvalue().encode("utf-8")
    assert stream.getvalue().count("vid\\xe9o.avi") == 3


@pytest.fixture
def command():
    token = recorded_command.set(["strain2d", "analyze", VIDEO])
    yield
    recorded_command.reset(token)


def test_a_result_folder_so_named_is_recorded_and_replaced(tmp_path, command):
    out = tmp_path / latin1("résultats")
    for overwrite in (False, True):
        with atomic_dir(out, overwrite=overwrite) as tmp:
            (tmp / latin1("données")).mkdir()
            (tmp / latin1("données") / VIDEO).write_bytes(b"x" if overwrite else b"first")
            (tmp / "summary.json").write_text("{}")
    assert (out / latin1("données") / VIDEO).read_bytes() == b"x"
    marker = strict_json(out / MARKER)
    assert marker["command"] == ["strain2d", "analyze", "vid\\xe9o.avi"]
    assert marker["folders"] == ["donn\\xe9es"]
    assert sorted(marker["files"]) == ["donn\\xe9es/vid\\xe9o.avi", "summary.json"]
    assert bytes.fromhex(marker["exact_names"]["donn\\xe9es/vid\\xe9o.avi"]) == (
        b"donn\xe9es/vid\xe9o.avi"
    )
    assert foreign_content(out) is None


def test_a_name_that_only_reads_alike_is_not_the_one_recorded(tmp_path, command):
    out = tmp_path / "run"
    with atomic_dir(out) as tmp:
        (tmp / VIDEO).write_bytes(b"x")
    (out / VIDEO).rename(out / "vid\\xe9o.avi")  # the user's file, named as the marker shows
    assert "vid\\xe9o.avi, which the earlier result did not write" in foreign_content(out)
    with pytest.raises(ValueError, match="nothing was replaced"):
        check_writable(out, overwrite=True)


def test_an_output_file_so_named_is_recorded_in_the_ledger_and_replaced(tmp_path, command):
    folder = tmp_path / latin1("Messdatén")
    folder.mkdir()
    tracks = folder / latin1("trajectoirés.csv")
    for overwrite, text in ((False, "first\n"), (True, "second\n")):
        with atomic_file(tracks, overwrite=overwrite) as tmp:
            tmp.write_text(text)
    assert tracks.read_text() == "second\n"
    ledger = strict_json(folder / LEDGER)
    assert list(ledger["files"]) == ["trajectoir\\xe9s.csv"]
    assert ledger["exact_names"] == {"trajectoir\\xe9s.csv": exact_name(tracks.name)}
    alike = folder / "trajectoir\\xe9s.csv"
    alike.write_text("second\n")  # the same content under the name the ledger shows
    with pytest.raises(ValueError, match="not a file this toolkit wrote"):
        check_writable(alike, overwrite=True, kind="file")


def test_a_library_writes_a_file_so_named_under_a_utf8_name(tmp_path):
    folder = tmp_path / latin1("Messdatén")
    folder.mkdir()
    for name in (VIDEO, "video.avi"):  # the file's own name, or only its folder's, not UTF-8
        with utf8_output(folder / name) as target:
            assert is_utf8(target) and target.suffix == ".avi"
            target.write_bytes(b"frames")
            assert is_utf8(target.resolve())  # PyVista resolves the names it is given
        assert (folder / name).read_bytes() == b"frames"
    with pytest.raises(RuntimeError), utf8_output(folder / latin1("écrit.avi")) as target:
        target.write_bytes(b"half")
        raise RuntimeError("the writer failed")
    assert sorted(p.name for p in folder.iterdir()) == sorted([VIDEO, "video.avi"])


def test_a_file_written_on_another_file_system_is_copied_into_place(tmp_path, monkeypatch):
    import errno

    rename = os.replace

    def across_devices(src, dst):
        if "tissue-strain-name-" in os.fspath(src):  # from the private folder: another disk
            raise OSError(errno.EXDEV, "Invalid cross-device link")
        rename(src, dst)

    monkeypatch.setattr(os, "replace", across_devices)
    with utf8_output(tmp_path / VIDEO) as target:
        target.write_bytes(b"frames")
    assert [p.name for p in tmp_path.iterdir()] == [VIDEO]
    assert (tmp_path / VIDEO).read_bytes() == b"frames"


def test_log_lines_show_such_names_readably():
    code = (
        "import logging, os, sys\n"
        "from tissue_core.cli import CommandLine, run_command\n"
        "cli = CommandLine('demo', 'A demonstration.')\n"
        "name = os.fsdecode(b'vid\\xe9o.avi')\n"
        "cli.command('go', lambda args: logging.getLogger('demo').warning('read %s', name) or 0)\n"
        "sys.exit(run_command('demo', cli, ['go']))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.decode("utf-8") == "WARNING: read vid\\xe9o.avi\n"
