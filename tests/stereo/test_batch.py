"""``stereo batch``: specimens of a manifest reconstructed as a batch; a failing one is reported,
a rerun keeps what is complete and the calibration is a column or an option for all."""

import json

from stereo.cli import main
from tissue_core.batch import differences


def test_a_stereo_batch_reconstructs_each_specimen_as_reconstruct_does(
    small_stereo, tmp_path, capsys
):
    s = small_stereo
    manifest = tmp_path / "specimens.csv"
    manifest.write_text(
        "specimen,left,right,calib,notes\n"
        f"sheet,{s.left},{s.right},{s.calib},as rendered\n"
        f"broken,{s.left},{tmp_path / 'missing'},{s.calib},right view lost\n"
    )
    options = ["--grid", "5x4", "--roi", "280,150,400,240"]
    out = tmp_path / "batch"
    assert main(["batch", str(manifest), *options, "--workers", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1].startswith("stereo batch: error: 1 of 2 runs failed"), err
    assert "broken: no such file or folder" in err and "manifest columns not used: notes" in err
    record = {r["name"]: r["status"] for r in json.loads((out / "batch.json").read_text())["runs"]}
    assert record == {"sheet": "done", "broken": "failed"}
    # the run is the one reconstruct makes
    alone = tmp_path / "alone"
    argv = ["reconstruct", "--calib", str(s.calib), "--left", str(s.left), "--right", str(s.right),
            *options, "--out", str(alone), "-q"]  # fmt: skip
    assert main(argv) == 0
    assert differences(alone, out / "runs" / "sheet") == []
    # a rerun makes only the failing one; the calibration can also be given for all
    manifest.write_text(
        f"specimen,left,right\nsheet,{s.left},{s.right}\nbroken,{s.left},{tmp_path / 'missing'}\n"
    )
    argv = ["batch", str(manifest), "--calib", str(s.calib), *options, "--workers", "1"]
    assert main([*argv, "--out", str(out)]) == 2
    log = (out / "batch.log").read_text()
    assert "batch of 2 runs: 1 complete already, 1 to run" in log
    # without a calibration nothing runs
    capsys.readouterr()
    assert main(["batch", str(manifest), *options, "--out", str(tmp_path / "none")]) == 2
    assert "give the calibration" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()
