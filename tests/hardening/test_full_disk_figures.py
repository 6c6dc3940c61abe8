"""A full disk while the figures are written (issue 22): the run ends with a
clear error naming the figure and what was kept (results.nc, summary.json),
exit status 3, no traceback and no half-written figure left behind.

The fault is injected where it happens: Pillow's image writer raises
``OSError(ENOSPC)`` (a tmpfs of a few kB would need root)."""

import errno
import json

import numpy as np
import PIL.Image
import pytest

import avblocks as av
from avblocks.cli import main


def _full_disk(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.fixture
def full_disk_for_images(monkeypatch):
    monkeypatch.setattr(PIL.Image.Image, "save", _full_disk)


def test_full_disk_while_writing_figures(tmp_path, monkeypatch, capsys,
                                         full_disk_for_images):
    monkeypatch.chdir(tmp_path)
    rc = main(["run", "waypoints", "--set", "agents=3", "--set", "simulation.t_final=1",
               "--out", "o", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 3, err
    assert "Traceback" not in err
    assert "could not write 'o/waypoints.png': the disk is full" in err
    assert "kept: o/results.nc, o/summary.json" in err
    res = av.Results.load(tmp_path / "o" / "results.nc")     # the data is whole
    assert np.asarray(res["fleet.pose"]).shape == (len(res.t), 3, 3)
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["write_errors"] and "waypoints.png" in s["write_errors"][0]
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["results.nc",
                                                                   "summary.json"]


def test_full_disk_for_the_default_trajectory_figure(tmp_path, monkeypatch, capsys,
                                                     full_disk_for_images):
    p = tmp_path / "s.yaml"
    p.write_text("""
blocks:
  fleet: {type: vehicles.Unicycle, pose0: {zeros: {shape: [2, 3]}}}
  c: {type: blocks.Constant, value: [[1.0, 0.0], [1.0, 0.1]]}
wires: [[c.y, fleet.cmd]]
simulation: {t_final: 0.5, dt: 0.1}
""")
    monkeypatch.chdir(tmp_path)
    rc = main(["run", str(p), "--out", "o", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 3 and "Traceback" not in err
    assert "could not write 'o/trajectories.png': the disk is full" in err
    assert "kept: o/results.nc" in err
    assert not list((tmp_path / "o").glob("*.png")) and not list((tmp_path / "o").glob(".*"))


def test_save_figure_names_the_file_and_leaves_nothing(tmp_path, full_disk_for_images):
    import matplotlib.pyplot as plt

    from avblocks.scenarios.report import save_figure
    fig = plt.figure()
    with pytest.raises(av.AvError, match="could not write '.*a.png': the disk is full"):
        save_figure(fig, tmp_path / "a.png")
    assert list(tmp_path.iterdir()) == []
    assert not plt.fignum_exists(fig.number)                 # closed all the same
    # vector formats do not go through Pillow: written
    assert save_figure(plt.figure(), tmp_path / "b.svg").stat().st_size > 0


def test_save_figure_formats_by_suffix(tmp_path):
    """Written whole under the real name, in the format the suffix names
    (no suffix: Matplotlib's default, PNG); nothing else left behind."""
    import matplotlib.pyplot as plt

    from avblocks.scenarios.report import save_figure
    heads = {"a": b"\x89PNG", "b.PNG": b"\x89PNG", "c.pdf": b"%PDF", "d.svg": b"<?xm"}
    for name, head in heads.items():
        assert save_figure(plt.figure(), tmp_path / name).read_bytes()[:4] == head
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(heads)
