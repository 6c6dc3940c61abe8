"""Plotting functions follow Matplotlib's habits: they draw into ``ax=`` (or
make a pyplot figure), so ``plt.savefig`` writes what was drawn."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402

import avblocks as av  # noqa: E402
import avblocks.viz  # noqa: E402,F401


def results(n=30, T=50):
    t = np.linspace(0, 5, T)
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pose = np.zeros((T, n, 3))
    pose[..., 0] = np.cos(a) * (1 + t[:, None])
    pose[..., 1] = np.sin(a) * (1 + t[:, None])
    pose[..., 2] = a
    flag = t[:, None] > (a[None] / a.max() * 5)
    return av.Results(t, {"fleet.pose": pose, "g.flag": flag, "g.v": pose[..., 0]})


def ink(path):
    """Fraction of coloured (not grey, not white) pixels: the data, not the
    axes."""
    img = np.asarray(Image.open(path).convert("RGB")).astype(int)
    spread = img.max(axis=2) - img.min(axis=2)
    return float((spread > 60).mean())


def test_plt_savefig_after_each_plot_function_is_not_blank(tmp_path):
    res = results()
    for i, fn in enumerate([lambda: av.viz.plot_trajectories(res),
                            lambda: av.viz.plot_trajectories(res, color="g.flag"),
                            lambda: av.viz.plot_trajectories(res, color="g.v"),
                            lambda: av.viz.plot_signals(res, "g.v"),
                            lambda: av.viz.plot_frame(res, t=2.0, color="g.flag")]):
        plt.close("all")
        fig = fn()
        assert plt.gcf() is fig
        plt.savefig(tmp_path / f"{i}.png")
        assert ink(tmp_path / f"{i}.png") > 0.0005, i
    plt.close("all")


def test_into_given_axes_and_colour_by_signal():
    res = results(n=4, T=11)
    fig, (a, b) = plt.subplots(1, 2)
    out = av.viz.plot_trajectories(res, ax=b, color="g.flag")
    assert out is fig and not a.collections
    from matplotlib.collections import LineCollection
    (lc,) = [c for c in b.collections if isinstance(c, LineCollection)]
    assert len(lc.get_segments()) == 4 * 10          # one per agent and step
    # segment colour = the flag at its start: grey (False) or red (True)
    red = np.array(matplotlib.colors.to_rgba("tab:red")[:3])
    flag = np.asarray(res["g.flag"])[:-1].T.reshape(-1)
    is_red = np.all(np.isclose(lc.get_colors()[:, :3], red), axis=1)
    np.testing.assert_array_equal(is_red, flag)
    plt.close(fig)


def test_many_agents_thin_lines_and_decimated():
    res = results(n=600, T=1000)
    fig = av.viz.plot_trajectories(res, max_points=100)
    from matplotlib.collections import LineCollection
    (lc,) = [c for c in fig.axes[0].collections if isinstance(c, LineCollection)]
    assert max(lc.get_linewidths()) < 0.5
    assert len(lc.get_segments()[0]) == 100
    plt.close(fig)
