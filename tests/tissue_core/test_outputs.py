"""Outputs never replace what the toolkit did not write."""

import errno
import hashlib
import json
import os
from pathlib import Path

import pytest

from tissue_core.errors import InputError
from tissue_core.outputs import (
    LEDGER,
    MARKER,
    atomic_dir,
    atomic_file,
    check_writable,
    foreign_content,
    read_marker,
    recorded_command,
    replaced_on_success,
)


def tree(folder: Path) -> dict[str, bytes | None]:
    """Every entry under ``folder`` with its bytes (None for folders)."""
    return {
        p.relative_to(folder).as_posix(): (p.read_bytes() if p.is_file() else None)
        for p in sorted(folder.rglob("*"))
    }


def write_result(out: Path, files=("a.csv", "figures/b.png"), **kwargs) -> None:
    with atomic_dir(out, **kwargs) as tmp:
        for name in files:
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp / name).write_text(name)


def test_a_result_carries_a_marker_listing_its_files(tmp_path):
    out = tmp_path / "run"
    token = recorded_command.set(["strain2d", "analyze", "v.avi"])
    try:
        write_result(out)
    finally:
        recorded_command.reset(token)
    marker = read_marker(out)
    assert sorted(marker["files"]) == ["a.csv", "figures/b.png"]
    assert marker["folders"] == ["figures"]
    assert marker["files"]["a.csv"]["size"] == 5
    assert marker["files"]["a.csv"]["sha256"] == hashlib.sha256(b"a.csv").hexdigest()
    assert marker["command"] == ["strain2d", "analyze", "v.avi"]
    assert marker["software"]["name"] == "tissue-strain" and marker["software"]["version"]
    assert foreign_content(out) is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no scratch left


@pytest.mark.parametrize("overwrite", [False, True])
def test_a_folder_of_the_users_is_never_replaced(tmp_path, overwrite):
    thesis = tmp_path / "thesis"
    (thesis / "chapters").mkdir(parents=True)
    (thesis / "chapters" / "one.tex").write_text("the work of years")
    before = tree(thesis)
    with pytest.raises(InputError, match=r"not a result of this toolkit.*left as it is"):
        write_result(thesis, overwrite=overwrite)
    assert tree(thesis) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["thesis"]


def test_a_users_file_inside_a_result_stops_the_overwrite(tmp_path):
    out = tmp_path / "run"
    write_result(out)
    with pytest.raises(InputError, match=r"exists .an earlier result.; pass --overwrite"):
        write_result(out)
    (out / "figures" / "my_annotations.svg").write_text("mine")
    before = tree(out)
    with pytest.raises(InputError, match=r"holds figures/my_annotations.svg, which the earlier"):
        write_result(out, overwrite=True)
    assert tree(out) == before
    (out / "figures" / "my_annotations.svg").unlink()
    (out / "notes").mkdir()  # an empty folder of the user's counts too
    with pytest.raises(InputError, match="holds notes"):
        write_result(out, overwrite=True)
    (out / "notes").rmdir()
    (out / ".DS_Store").write_bytes(b"\0")  # what a file browser adds does not
    write_result(out, files=["c.txt"], overwrite=True)
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "c.txt"]


def test_nested_results_are_the_toolkits(tmp_path):
    data = tmp_path / "study_data"
    write_result(data, files=["S01.avi", "runs/.keep"])
    write_result(data / "runs" / "S01")  # strain2d analyze --out inside the study folder
    assert foreign_content(data) is None
    (data / "runs" / "S01" / "mine.txt").write_text("mine")
    assert foreign_content(data) == "runs/S01/mine.txt, which the earlier result did not write"
    with pytest.raises(InputError, match=r"runs/S01/mine.txt"):
        write_result(data, overwrite=True)
    (data / "runs" / "S01" / "mine.txt").unlink()
    write_result(data, files=["S01.avi"], overwrite=True)
    assert sorted(p.name for p in data.iterdir()) == [MARKER, "S01.avi"]


def test_a_damaged_or_foreign_marker_does_not_count(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "x.csv").write_text("x")
    for text in ("{", "[]", json.dumps({"kind": "other", "files": {"x.csv": {}}}),
                 json.dumps({"kind": "tissue-strain result", "files": ["x.csv"]})):  # fmt: skip
        (out / MARKER).write_text(text)
        assert read_marker(out) is None
        with pytest.raises(InputError, match="not a result"):
            write_result(out, overwrite=True)
    assert (out / "x.csv").read_text() == "x"


def test_a_copied_or_crafted_marker_does_not_let_anything_go(tmp_path):
    """A marker that lists what is not there, or paths outside, changes nothing."""
    out = tmp_path / "run"
    write_result(out)
    marker = json.loads((out / MARKER).read_text())
    marker["files"].update({"../outside.txt": {}, "/etc/passwd": {}})
    marker["folders"] += ["..", "/"]
    (out / MARKER).write_text(json.dumps(marker))
    (tmp_path / "outside.txt").write_text("mine")
    (out / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match=r"notes.txt, which the earlier result did not write"):
        write_result(out, overwrite=True)
    (out / "notes.txt").unlink()
    write_result(out, files=["c.txt"], overwrite=True)
    assert (tmp_path / "outside.txt").read_text() == "mine"


def test_a_file_edited_after_the_toolkit_wrote_it_stops_the_overwrite(tmp_path):
    out = tmp_path / "run"
    write_result(out)
    report = out / "a.csv"
    report.write_text("a.csv, with the user's notes")  # edited in place
    with pytest.raises(InputError, match=r"a.csv, which was changed after the toolkit wrote it"):
        write_result(out, overwrite=True)
    report.write_text("a.csv")  # the same content again (a copy, a touch): it is the result
    write_result(out, files=["c.txt"], overwrite=True)
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "c.txt"]


def test_a_result_that_holds_a_nested_result_can_be_replaced(tmp_path):
    out = tmp_path / "study"
    with atomic_dir(out) as tmp:
        (tmp / "runs").mkdir()
        with atomic_dir(tmp / "runs" / "S01") as inner:
            (inner / "a.csv").write_text("a")
    assert foreign_content(out) is None
    write_result(out, overwrite=True)


def test_an_unreadable_subfolder_stops_the_overwrite(tmp_path, monkeypatch):
    out = tmp_path / "run"
    write_result(out)
    real_walk = os.walk

    def walk(top, onerror=None, **kwargs):  # as if figures/ could not be listed
        for entry in real_walk(top, **kwargs):
            if entry[0].endswith("figures"):
                onerror(PermissionError(13, "Permission denied", entry[0]))
            yield entry

    monkeypatch.setattr(os, "walk", walk)
    with pytest.raises(InputError, match="figures, which cannot be read"):
        write_result(out, overwrite=True)
    monkeypatch.undo()
    assert (out / "figures" / "b.png").read_text() == "figures/b.png"


def test_a_failed_rename_puts_the_earlier_result_back(tmp_path, monkeypatch):
    out = tmp_path / "run"
    write_result(out)
    before = tree(out)
    real_replace = os.replace

    def replace(src, dst):
        if ".tmp-" in str(src):  # the new result's rename fails (Ctrl-C, a full disk ...)
            raise KeyboardInterrupt
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        write_result(out, files=["c.txt"], overwrite=True)
    monkeypatch.undo()
    assert tree(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_empty_folder_is_used_and_symlinks_are_refused(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    write_result(empty)
    assert read_marker(empty) is not None
    link = tmp_path / "link"
    link.symlink_to(empty, target_is_directory=True)
    with pytest.raises(InputError, match="symbolic link"):
        write_result(link, overwrite=True)
    assert read_marker(empty) is not None


def test_outputs_never_replace_inputs_or_the_working_directory(tmp_path, monkeypatch):
    data = tmp_path / "data"
    data.mkdir()
    video = data / "v.avi"
    video.write_bytes(b"video")
    for out, message in (
        (data, "would replace the input"),
        (data / "run", "inside the input folder"),
    ):
        with pytest.raises(InputError, match=message):
            check_writable(out, overwrite=True, inputs=[data])
    with pytest.raises(InputError, match="would replace the input"):
        check_writable(video, overwrite=True, kind="file", inputs=[video])
    monkeypatch.chdir(data)
    for out in (".", "..", str(tmp_path)):
        with pytest.raises(InputError, match="working directory"):
            check_writable(out, overwrite=True)
    with pytest.raises(InputError, match="does not exist"):
        check_writable(tmp_path / "no" / "run", overwrite=False)
    assert video.read_bytes() == b"video"


def test_an_error_inside_leaves_nothing_and_names_the_output(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(OSError, match=r"run/figures/x.png") as info:
        with atomic_dir(out) as tmp:
            open(tmp / "figures" / "x.png", "rb")
    assert ".tmp-" not in str(info.value)
    with pytest.raises(InputError) as info:
        with atomic_dir(out) as tmp:
            raise InputError(f"cannot write {tmp / 'a.csv'}")
    assert str(info.value) == f"cannot write {out / 'a.csv'}"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT, errno.EFBIG])
def test_a_full_disk_names_the_output_being_written(tmp_path, code):
    """``write`` and ``close`` raise ENOSPC without a file name: the output is named instead."""

    def fill(path: Path, named: bool) -> None:
        with open(path, "w") as f:
            f.write("half a table")
        args = (code, os.strerror(code), *([str(path)] if named else []))
        raise OSError(*args)

    out = tmp_path / "run"
    with pytest.raises(OSError) as info, atomic_dir(out) as tmp:
        fill(tmp / "tracks.csv", named=False)
    assert info.value.filename == str(out)
    assert str(info.value) == f"[Errno {code}] {os.strerror(code)}: '{out}'"
    with pytest.raises(OSError) as info, atomic_dir(out) as tmp:
        fill(tmp / "tracks.csv", named=True)  # named, but by its scratch name
    assert info.value.filename == str(out / "tracks.csv")
    path = tmp_path / "tracks.csv"
    with pytest.raises(OSError) as info, atomic_file(path) as tmp:
        fill(tmp, named=False)
    assert info.value.filename == str(path)
    with pytest.raises(OSError) as info, replaced_on_success(path) as tmp:
        fill(tmp, named=False)
    assert info.value.filename == str(path)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(OSError) as info, atomic_dir(out):  # not a write: nothing to name
        raise OSError(errno.EIO, os.strerror(errno.EIO))
    assert info.value.filename is None


def test_a_file_is_replaced_only_when_the_toolkit_wrote_it(tmp_path):
    mine = tmp_path / "tracks.csv"
    mine.write_text("frame,point,x,y,visible,quality\n0,0,1,2,1,1\n")  # the user's own tracks
    for overwrite in (False, True):
        with pytest.raises(InputError, match="not a file this toolkit wrote"):
            with atomic_file(mine, overwrite=overwrite) as tmp:
                tmp.write_text("frame,point,x,y\n")
    assert mine.read_text().startswith("frame,point,x,y,visible,quality\n0,0,1,2")
    ours = tmp_path / "t.csv"
    with atomic_file(ours) as tmp:
        tmp.write_text("first\n")
    ledger = json.loads((tmp_path / LEDGER).read_text())
    assert ledger["files"]["t.csv"]["sha256"] == hashlib.sha256(b"first\n").hexdigest()
    with pytest.raises(InputError, match=r"exists \(an earlier result\); pass --overwrite"):
        check_writable(ours, overwrite=False, kind="file")
    with atomic_file(ours, overwrite=True) as tmp:
        tmp.write_text("second\n")
    assert ours.read_text() == "second\n"
    ours.write_text("second, edited\n")  # the user edits it: it is theirs now
    with pytest.raises(InputError, match="not a file this toolkit wrote"):
        check_writable(ours, overwrite=True, kind="file")
    assert sorted(p.name for p in tmp_path.iterdir()) == [LEDGER, "t.csv", "tracks.csv"]


def test_finished_outputs_get_the_umask_permissions(tmp_path):
    mask = os.umask(0o027)
    try:
        write_result(tmp_path / "run")
        with atomic_file(tmp_path / "t.csv") as tmp:
            tmp.write_text("x")
    finally:
        os.umask(mask)
    assert (tmp_path / "run").stat().st_mode & 0o777 == 0o750
    assert (tmp_path / "t.csv").stat().st_mode & 0o777 == 0o640


# ---- scratch that runs killed outright (SIGKILL) left behind --------------------------------

#: a process of its own that writes with the toolkit's writers and is killed (SIGKILL) inside
#: the block, or between the two renames that replace an earlier result (``between``)
KILLED_WRITER = """
import os, signal, sys
from pathlib import Path
from tissue_core import outputs

how, target = sys.argv[1], Path(sys.argv[2])
if how == "between":
    real = os.replace

    def replace(src, dst):
        real(src, dst)
        if Path(dst).parent.name.startswith(f".{target.name}.old-"):  # the earlier result moved
            os.kill(os.getpid(), signal.SIGKILL)

    os.replace = replace
    with outputs.atomic_dir(target, overwrite=True) as tmp:
        (tmp / "new.csv").write_text("the new result")
elif how == "dir":
    with outputs.atomic_dir(target) as tmp:
        (tmp / "half.csv").write_text("half a result")
        os.kill(os.getpid(), signal.SIGKILL)
elif how == "file":
    with outputs.atomic_file(target) as tmp:
        tmp.write_text("half a file")
        os.kill(os.getpid(), signal.SIGKILL)
else:
    with outputs.replaced_on_success(target) as tmp:
        tmp.write_text("half a file")
        os.kill(os.getpid(), signal.SIGKILL)
"""


def killed_while_writing(how: str, target: Path) -> list[str]:
    """Run KILLED_WRITER; the scratch it left beside ``target``."""
    import signal
    import subprocess
    import sys

    repo = Path(__file__).resolve().parents[2]
    done = subprocess.run(
        [sys.executable, "-c", KILLED_WRITER, how, str(target)],
        env={**os.environ, "PYTHONPATH": str(repo)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == -signal.SIGKILL, done.stderr
    return sorted(p.name for p in target.parent.iterdir() if ".tmp-" in p.name or ".old-" in p.name)


def test_scratch_names_carry_their_owner(tmp_path):
    import re
    import socket

    with open("/proc/self/stat") as f:
        start = f.read().rsplit(")", 1)[1].split()[19]
    host = re.sub(r"[^A-Za-z0-9.-]", "_", socket.gethostname())[:32]  # long names cut
    with atomic_dir(tmp_path / "run") as tmp:
        (scratch,) = [p.name for p in tmp_path.iterdir()]
        assert tmp.name == scratch
    assert scratch.startswith(f".run.tmp-{os.getpid()}-{start}@{host}"), scratch


@pytest.mark.parametrize("how", ["dir", "file", "replaced"])
def test_the_scratch_of_a_killed_run_is_removed_by_the_next_one(how, tmp_path):
    target = tmp_path / ("run" if how == "dir" else "tracks.csv")
    left = killed_while_writing(how, target)
    assert len(left) == 1 and left[0].startswith(f".{target.name}.tmp-"), left
    if how == "dir":
        write_result(target)
    elif how == "file":
        with atomic_file(target) as tmp:
            tmp.write_text("whole")
    else:
        from tissue_core.outputs import replaced_on_success

        with replaced_on_success(target) as tmp:
            tmp.write_text("whole")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [target.name, *([LEDGER] if how == "file" else [])]
    )


def test_a_killed_replacement_puts_the_earlier_result_back(tmp_path):
    out = tmp_path / "run"
    write_result(out)
    before = tree(out)
    left = killed_while_writing("between", out)  # killed with the earlier result set aside
    assert not out.exists()
    assert [name.split("-")[0] for name in left] == [".run.old", ".run.tmp"], left
    # the next command finds the earlier result where it was, and does not replace it unasked
    with pytest.raises(InputError, match="exists \\(an earlier result\\)"):
        check_writable(out, overwrite=False)
    assert tree(out) == before and foreign_content(out) is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_scratch_of_a_live_owner_another_host_or_another_form_is_kept(tmp_path):
    import subprocess
    import sys

    from tissue_core.outputs import remove_stale_scratch

    with atomic_dir(tmp_path / "mine") as tmp:  # this process's own scratch: alive
        alive = tmp.name
    asleep = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        with open(f"/proc/{asleep.pid}/stat") as f:
            start = f.read().rsplit(")", 1)[1].split()[19]
        host = alive.split("@")[1]
        kept = [
            alive.replace(".mine.", ".run."),  # this process: alive
            f".run.tmp-{asleep.pid}-{start}@{host}@abcd1234",  # another process, alive
            ".run.tmp-1-1@another-host@abcd1234",  # another host: cannot be told
            ".run.tmp-abcd1234",  # not of the toolkit's form
            ".run.old-12ab",
        ]
        gone = [
            f".run.tmp-{asleep.pid}-{int(start) + 1}@{host}@abcd1234",  # its pid, used again
            f".run.old-{asleep.pid}-{int(start) - 1}@{host}@abcd1234",
        ]
        for name in [*kept, *gone]:
            (tmp_path / name).mkdir()
        (tmp_path / kept[0] / "half.csv").write_text("x")
        assert sorted(p.name for p in remove_stale_scratch(tmp_path / "run")) == sorted(gone)
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*kept, "mine"])
    finally:
        asleep.kill()
        asleep.wait()
