"""Movies decode with the expected frame count and size; the Animation2D block."""

import numpy as np
import pytest
from PIL import Image

import avblocks as av
import avblocks.viz as viz

pytest.importorskip("imageio_ffmpeg")

SMALL = dict(figsize=(2.0, 1.6), dpi=80)      # 160 x 128 pixels


def straight_run(T=12, n=3):
    t = np.arange(T) * 0.1
    pose = np.zeros((T, n, 3))
    pose[:, :, 0] = t[:, None]
    pose[:, :, 1] = np.arange(n)
    informed = np.broadcast_to(t[:, None] > 0.5, (T, n))
    return av.Results(t, {"fleet.pose": pose, "fleet.informed": informed})


def test_mp4_decodes_with_frame_count_and_size(tmp_path):
    res = straight_run(T=12)
    path = viz.save_movie(res, tmp_path / "run.mp4", fps=10, every=2, trail=0.5,
                          color="fleet.informed", **SMALL)
    frames, fps = viz.read_video(path)
    assert frames.shape == (6, 128, 160, 3)
    assert fps == pytest.approx(10)
    # a rendered agent is not all white
    assert frames[-1].min() < 200


def test_odd_frame_size_is_cropped_to_even(tmp_path):
    res = straight_run(T=4)
    path = viz.save_movie(res, tmp_path / "odd.mp4", fps=5, figsize=(1.01, 1.01), dpi=100)  # 101 px
    frames, _ = viz.read_video(path)
    assert frames.shape == (4, 100, 100, 3)


def test_gif_frame_count_and_size(tmp_path):
    res = straight_run(T=9)
    path = viz.save_movie(res, tmp_path / "run.gif", fps=10, every=3, **SMALL)
    with Image.open(path) as im:
        assert im.size == (160, 128)
        assert im.n_frames == 3
        assert im.info["duration"] == 100


def test_default_fps_is_real_time_and_pose_found():
    anim = viz.animate(straight_run(), every=2, **SMALL)
    assert anim.key == "fleet.pose"
    assert anim.fps_default == pytest.approx(5.0)
    assert len(anim) == 6
    anim.close()


def test_no_pose_signal_is_an_error():
    res = av.Results(np.arange(3.0), {"a.y": np.zeros((3, 2, 3))})
    with pytest.raises(av.ParameterError, match="ends in '.pose'"):
        viz.animate(res)


def test_html5_video_for_notebooks():
    anim = viz.animate(straight_run(T=3), **SMALL)
    html = anim._repr_html_()
    assert html.startswith("<video") and "base64," in html
    anim.close()


def test_unknown_suffix():
    with pytest.raises(av.ParameterError, match="unknown movie format"):
        viz.MovieWriter("x.png")


def sim_diagram(**anim_kw):
    n = 4
    pose0 = np.c_[np.zeros(n), np.arange(n, dtype=float), np.zeros(n)]
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=pose0), name="fleet")
    c = d.add(av.blocks.Constant(np.tile([1.0, 0.3], (n, 1))), name="c")
    d.connect(c.y, f.cmd)
    a = d.add(viz.Animation2D(n, **anim_kw), name="anim")
    d.connect(f.pose, a.pose)
    return d, a, f


def test_animation_block_streams_a_movie(tmp_path):
    d, a, f = sim_diagram(every=4, trail=1.0, movie=tmp_path / "live.mp4", **SMALL)
    av.simulate(d, 2.0, dt=0.05, log=[f.pose])       # 41 major steps incl. t0
    assert a.block.path == tmp_path / "live.mp4"
    frames, fps = viz.read_video(a.block.path)
    assert frames.shape == (11, 128, 160, 3)
    assert fps == pytest.approx(5.0)                  # real time: 1 / (0.05 * 4)
    assert a.block.frame_list == []


def test_animation_block_keeps_frames_offscreen_with_inputs(tmp_path):
    n = 4
    d, a, f = sim_diagram(every=10, color_input=True, collision_input=True, **SMALL)
    flag = d.add(av.blocks.Constant(np.array([True, False, True, False])), name="flag")
    d.connect(flag.y, a.color)
    d.connect(flag.y, a.collision)
    av.simulate(d, 1.0, dt=0.05)
    blk = a.block
    assert len(blk.frame_list) == 3 and blk.frame_list[0].shape == (128, 160, 3)
    assert blk.scene.n == n
    path = blk.save(tmp_path / "kept.gif", fps=4)
    with Image.open(path) as im:
        assert im.n_frames == 3


def test_plain_colour_or_signal():
    res = straight_run(T=3, n=1)
    a = viz.animate(res, color="red", extent=(-1, 1, -1, 1), drawing="robot", size=0.8,
                    timestamp=False, **SMALL)
    img = a.render(0)
    r, c = a.scene.pixel(0.0, 0.2)
    assert tuple(img[r, c]) == (255, 0, 0)
    a.close()
    b = viz.animate(res, color="fleet.informed", **SMALL)
    assert b.color.shape == (3, 1)
    b.close()
