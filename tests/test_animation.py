"""The animation (`lj.animate`, `lj.save_gif`) and the `animate` command.

The point of the animation is to show stick-slip, so the tests check that a stuck
mass really stands still: in the artists of every frame (what matplotlib draws)
and in the pixels of the GIF the command writes.
"""

import math

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.cli._animate import register
from locomotion_jax.run._animation import SLIP_COLOR, STUCK_COLOR, stuck_masks
from matplotlib.animation import AbstractMovieWriter
from matplotlib.colors import to_rgb, to_rgba
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle
from PIL import GifImagePlugin, Image
from plugin_app import plugin_app
from typer.testing import CliRunner


OMEGA = 2.0  # 0.2 wn1: the paper's stick-slip case (Fig. 5a)
T_END = 12.0
FRAMES = 24


def _window(t_end=T_END, frames=FRAMES):
    """The frame times the command uses by default: two actuation periods before t_end."""
    return np.linspace(t_end - 2 * (2 * math.pi / OMEGA), t_end, frames)


@pytest.fixture(scope="module")
def ssl():
    p = lj.Params(omega=OMEGA)
    return p, lj.simulate(p, T_END, save_at=_window())


class _Recorder(AbstractMovieWriter):
    """A movie writer that keeps, for every frame, what the artists draw (writes no file)."""

    def __init__(self):
        super().__init__(fps=10)
        self.frames = []

    def setup(self, fig, outfile, dpi=None):
        # Abstract in the base class, but implemented there (it keeps fig, outfile and dpi).
        super().setup(fig, outfile, dpi)  # pyright: ignore[reportAbstractUsage]

    def grab_frame(self, **savefig_kwargs):
        art = {a.get_gid(): a for a in self.fig.findobj() if a.get_gid()}
        rec = {}
        for k in (1, 2):
            box, anchor = art[f"mass{k}"], art[f"anchor{k}"]
            assert isinstance(box, Rectangle) and isinstance(anchor, Line2D)
            rec[f"x{k}"] = box.get_x() + box.get_width() / 2
            rec[f"face{k}"] = box.get_facecolor()
            rec[f"anchor{k}"] = anchor.get_visible()
            rec[f"anchor_x{k}"] = float(np.asarray(anchor.get_xdata())[0])
        spring = art["spring"]
        assert isinstance(spring, Line2D)
        xs = np.asarray(spring.get_xdata())
        rec["spring"] = (float(xs[0]), float(xs[-1]))
        self.frames.append(rec)

    def finish(self):
        pass


def test_artists_stuck_mass_stands_still(ssl, tmp_path):
    p, traj = ssl
    anim = lj.animate(traj, p)
    rec = _Recorder()
    anim.save(tmp_path / "unused.gif", writer=rec)
    assert len(rec.frames) == FRAMES
    stuck = stuck_masks(traj.mode)
    xs = (np.asarray(traj.x1), np.asarray(traj.x2))
    for k in (1, 2):
        drawn = np.array([f[f"x{k}"] for f in rec.frames])
        s = stuck[k - 1]
        # The case really sticks and slips in this window, for both masses.
        assert s.sum() >= 5 and (~s).sum() >= 5
        # Each frame draws the saved state: the block, the anchor and the spring's end.
        np.testing.assert_allclose(drawn, xs[k - 1], rtol=0, atol=1e-12)
        np.testing.assert_allclose([f[f"anchor_x{k}"] for f in rec.frames], xs[k - 1], rtol=0, atol=1e-12)
        np.testing.assert_allclose([f["spring"][k - 1] for f in rec.frames], xs[k - 1], rtol=0, atol=1e-12)
        # Stuck: red and anchored; slipping: blue, no anchor.
        for f, st in zip(rec.frames, s):
            assert f[f"anchor{k}"] == bool(st)
            assert f[f"face{k}"] == pytest.approx(to_rgba(STUCK_COLOR if st else SLIP_COLOR))
        # A stuck mass stands still: across consecutive stuck frames its drawn position is unchanged.
        both = s[1:] & s[:-1]
        assert both.sum() >= 3
        assert np.all(np.diff(drawn)[both] == 0.0)
        # ... while the pictures do move: the mass travels between its stuck intervals.
        assert np.ptp(drawn) > 0.02


def test_animate_rejects_bad_input(ssl, tmp_path):
    p, traj = ssl
    with pytest.raises(ValueError, match="t_range"):
        lj.animate(traj, p, t_range=(100.0, 200.0))
    # A batch of two (the same run twice, shifted), built without compiling a batched simulation.
    batch = lj.Params.stack([p, p])
    tr2 = jax.tree_util.tree_map(lambda x: jnp.stack([x, x + 1.0]) if x.dtype.kind == "f" else jnp.stack([x, x]), traj)
    with pytest.raises(ValueError, match="index"):
        lj.animate(tr2, batch[0])
    with pytest.raises(ValueError, match="one configuration"):
        lj.animate(tr2, batch, index=(0,))
    # A batch member is drawn with index=.
    rec = _Recorder()
    lj.animate(tr2, batch[1], index=(1,), trace=False).save(tmp_path / "unused.gif", writer=rec)
    np.testing.assert_allclose([f["x2"] for f in rec.frames], np.asarray(traj.x2) + 1.0, atol=1e-12)


def _blocks(frame: np.ndarray, color: str, top: int) -> list[tuple[float, float]]:
    """Column spans of the blocks of `color` in the scene (rows above `top`): (left, right) pixels.

    A block is a run of columns with at least 10 pixels of the colour (the label and the
    anchor are far thinner).
    """
    rgb = np.asarray(to_rgb(color)) * 255
    near = np.all(np.abs(frame[:top].astype(float) - rgb) < 40, axis=-1)
    cols = near.sum(axis=0) >= 10
    spans, start = [], None
    for j, c in enumerate(np.append(cols, False)):
        if c and start is None:
            start = j
        elif not c and start is not None:
            spans.append((start, j - 1))
            start = None
    return spans


def test_cli_writes_gif_and_stuck_mass_stands_still_in_it(ssl, tmp_path):
    p, traj = ssl
    out = tmp_path / "gifs" / "ssl.gif"
    args = [
        "animate",
        "--omega",
        str(OMEGA),
        "--t-end",
        str(T_END),
        "--frames",
        str(FRAMES),
        "--dpi",
        "50",
        "--out",
        str(out),
    ]
    res = CliRunner().invoke(plugin_app(register), args)
    assert res.exit_code == 0, res.output
    assert out.exists() and out.stat().st_size > 0
    assert "m1 stuck in" in res.output
    img = Image.open(out)
    assert img.format == "GIF" and isinstance(img, GifImagePlugin.GifImageFile) and img.n_frames == FRAMES
    frames = []
    for i in range(img.n_frames):
        img.seek(i)
        frames.append(np.asarray(img.convert("RGB")))
    top = frames[0].shape[0] // 2  # the scene is the upper panel; the lower one plots displacements
    stuck = stuck_masks(traj.mode)  # the command saves the same times as the fixture
    centre = {1: [], 2: []}
    for f, s1, s2 in zip(frames, *stuck):
        red, blue = _blocks(f, STUCK_COLOR, top), _blocks(f, SLIP_COLOR, top)
        assert len(red) == int(s1) + int(s2) and len(blue) == 2 - len(red)
        # Mass 1 is the left block (x1 < x2).
        spans = sorted([(sp, True) for sp in red] + [(sp, False) for sp in blue])
        for k, ((lo, hi), is_red), st in zip((1, 2), spans, (s1, s2)):
            assert is_red == bool(st)
            centre[k].append((lo + hi) / 2)
    for k in (1, 2):
        c = np.asarray(centre[k])
        s = stuck[k - 1]
        both = s[1:] & s[:-1]
        assert both.sum() >= 3
        # In the GIF a stuck mass does not move by a single pixel ...
        assert np.all(np.diff(c)[both] == 0)
        # ... and the masses do visibly move over the clip.
        assert np.ptp(c) >= 2


def test_cli_errors_are_reported(tmp_path):
    app = plugin_app(register)
    res = CliRunner().invoke(app, ["animate", "--out", str(tmp_path / "x.png")])
    assert res.exit_code == 2 and "Error: --out must name a .gif" in res.output
    res = CliRunner().invoke(app, ["animate", "--t-from", "5", "--t-end", "4", "--out", str(tmp_path / "x.gif")])
    assert res.exit_code == 2 and "--t-from" in res.output
    res = CliRunner().invoke(app, ["animate", "--mu-s", "0.1", "--out", str(tmp_path / "x.gif")])
    assert res.exit_code == 2 and "mu_s" in res.output
    assert not (tmp_path / "x.gif").exists()


def test_cli_liftoff(tmp_path):
    # omega = 23, a = 0.1 lifts mass 1 off at t = 0.167 (strict contact: the run stops there).
    app = plugin_app(register)
    out = tmp_path / "lift.gif"
    # As many frames as the fixture: the same compiled simulation serves.
    common = [
        "animate",
        "--omega",
        "23",
        "--a",
        "0.1",
        "--frames",
        str(FRAMES),
        "--dpi",
        "30",
        "--no-trace",
        "--out",
        str(out),
    ]
    res = CliRunner().invoke(app, common + ["--t-end", "3"])
    assert res.exit_code == 2 and "lift-off at t = 0.1667" in res.output and not out.exists()
    # A span that contains the lift-off: the frames before it are drawn, and the command says so.
    res = CliRunner().invoke(app, common + ["--t-from", "0", "--t-end", "0.25"])
    assert res.exit_code == 0, res.output
    assert "warning: lift-off at t = 0.1667" in res.output
    img = Image.open(out)
    assert isinstance(img, GifImagePlugin.GifImageFile)
    assert img.n_frames == np.sum(np.linspace(0, 0.25, FRAMES) < 0.1666)  # the states saved before the lift-off
