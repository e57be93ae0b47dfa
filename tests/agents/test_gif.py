"""The demo's time-lapse GIF: frames spread over the whole video, the GIF's size, rate and length, and the CLI rule."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from agents.cli import main
from agents.plotting import GIF_FPS, GIF_SECONDS, GIF_SIZE, video_to_gif


def bar_video(path, n_frames: int, size=(480, 360)) -> None:
    """An MP4 whose frame k is black with a white vertical bar at x = k / (n_frames - 1) of the width."""
    import imageio.v2 as iio

    w, h = size
    with iio.get_writer(path, format="FFMPEG", fps=25, codec="libx264", macro_block_size=8) as writer:
        for k in range(n_frames):
            frame = np.zeros((h, w, 3), dtype=np.uint8)
            x = round(k * (w - 16) / (n_frames - 1))
            frame[:, x : x + 16] = 255
            writer.append_data(frame)


def bar_position(image: Image.Image) -> float:
    """Where the white bar of a GIF frame is, as a fraction of the width (its brightest columns' centre)."""
    grey = np.asarray(image.convert("L"), dtype=float).mean(axis=0)
    cols = np.flatnonzero(grey > 0.5 * grey.max())
    return float(cols.mean() / (len(grey) - 1))


def test_the_gif_spreads_its_frames_over_the_whole_video(tmp_path):
    video = tmp_path / "walk.mp4"
    bar_video(video, n_frames=121)
    gif = video_to_gif(video, tmp_path / "out" / "walk.gif")
    with Image.open(gif) as im:
        assert im.size == GIF_SIZE == (320, 240)
        n = im.n_frames
        assert n == round(GIF_SECONDS * GIF_FPS) == 40
        assert im.info["duration"] == 1000 // GIF_FPS  # ms per frame: 40 frames play for 4 s
        positions = []
        for k in range(n):
            im.seek(k)
            positions.append(bar_position(im))
    # frame i of the GIF is video frame round(i * 120 / 39): the bar sweeps from the left edge to the right one
    expected = [(round(i * 120 / 39) * (480 - 16) / 120 + 7.5) / 479 for i in range(n)]
    assert np.allclose(positions, expected, atol=0.02)
    assert positions[0] < 0.05 and positions[-1] > 0.95


def test_a_video_shorter_than_the_gif_gives_every_frame_once(tmp_path):
    video = tmp_path / "short.mp4"
    bar_video(video, n_frames=12)
    with Image.open(video_to_gif(video, tmp_path / "short.gif")) as im:
        assert im.n_frames == 12


@pytest.mark.parametrize("kwargs", [{"seconds": 0.0}, {"size": (0, 240)}, {"colors": 1}])
def test_bad_gif_settings_are_refused(tmp_path, kwargs):
    video = tmp_path / "v.mp4"
    bar_video(video, n_frames=4)
    with pytest.raises(ValueError, match=r"video_to_gif\.(seconds|size|colors)"):
        video_to_gif(video, tmp_path / "v.gif", **kwargs)


def test_demo_refuses_a_gif_without_the_video(tmp_path, capsys):
    code = main(["demo", "--out", str(tmp_path / "d"), "--no-video", "--gif", str(tmp_path / "d.gif")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and "--gif" in err[0] and "--no-video" in err[0]
    assert not (tmp_path / "d").exists()
