"""Frames that explain an episode (rmm_envs.views) and the guardians' signals() hook."""

from __future__ import annotations

import importlib.util
import math

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401  (registers the envs)
from rmm_envs.views import EpisodeRecorder, Window, signal_groups, view_for
from rmm_envs.views.base import BODY_OUTLINE, COLLISION, DRIVER, GOAL, GUARDIAN, OBSTACLE, WALL

_HAS = {m: importlib.util.find_spec(m) is not None for m in ("pybullet", "mujoco", "pymunk")}


def _needs(module: str):
    return pytest.mark.skipif(not _HAS[module], reason=f"needs {module}")


#: env id, the index of the position coordinate moved by the hand-made trajectory
ENVS = [
    pytest.param("Dubins4DParallel-v0", 0, id="Dubins4D"),
    pytest.param("Dubins4DMapParallel-v0", 0, id="Dubins4DMap", marks=_needs("pymunk")),
    pytest.param("Dubins3DMazeParallel-v0", 0, id="Dubins3DMaze"),
    pytest.param("QuadrotorRoomParallel-v0", 0, id="QuadrotorRoom", marks=_needs("pybullet")),
    pytest.param("CartPoleParallel-v0", 0, id="CartPole"),
    pytest.param("InvertedPendulumParallel-v0", 1, id="InvertedPendulum", marks=_needs("mujoco")),
]


@pytest.fixture(scope="module")
def envs():
    made: dict = {}

    def get(env_id):
        if env_id not in made:
            made[env_id] = gym.make(env_id, clock="fixed:5")
        return made[env_id]

    yield get
    for e in made.values():
        e.close()


def _pattern(k: int) -> bool:
    return k % 10 >= 6  # the guardian flag on for 4 steps in every 10


def _episode(env, rec: EpisodeRecorder, steps: int = 30, seed: int = 4) -> list[bool]:
    """Steps with the guardian flag on by :func:`_pattern` (the driver's own control); the flags sent."""
    space = env.unwrapped.action_space
    _, info = env.reset(seed=seed)
    rec.begin()
    sent = []
    for k in range(steps):
        on = _pattern(k)
        action = space.active(info["nominal_control"]) if on else space.inactive()
        _, _, term, trunc, info = env.step(action)
        rec.record(info, {"demo": float(k), "demo_threshold": 5.0})
        sent.append(on)
        if term or trunc:
            break
    return sent


def _panel_window(view) -> Window:
    return view.top if hasattr(view, "top") else view.window


@pytest.mark.parametrize("env_id, _coord", ENVS)
def test_frames_have_the_size_and_the_strip_shows_the_recorded_flags(envs, env_id, _coord):
    env = envs(env_id)
    rec = EpisodeRecorder(env)
    calls = []
    draw_static = rec.view.draw_static
    rec.view.draw_static = lambda *a: (calls.append(1), draw_static(*a))[1]  # type: ignore[method-assign]  # counting
    _episode(env, rec)
    assert len(calls) == rec.static_draws == 1  # once per episode, not per frame
    frames = list(rec.frames(every=3))
    assert len(calls) == 1
    h, w = rec.frame_size
    assert h == rec.view.height + rec.strip_height
    for f in frames:
        assert f.shape == (h, w, 3) and f.dtype == np.uint8
    assert rec.n_steps >= 1
    # the non-blocking env applies each step's action in the next interval: the flags recorded are
    # the env's own (info / its statistics), and they match the episode statistics
    stats = env.unwrapped.episode_statistics()
    assert rec.active_steps == stats["n_active_ctrl_env_steps"]
    # the strip's intervention lane is orange exactly over the recorded intervals
    last = rec.frame()
    lane_y = rec.view.height + sum(rec.lane_rows) // 2
    for k in range(1, rec.n_steps + 1):
        a, b = rec.times[k - 1], rec.times[k]
        xa, xb = rec._time_x(a), rec._time_x(b)
        if xb - xa < 4:
            continue
        x = int(round((xa + xb) / 2))
        colour = tuple(last[lane_y, x])
        assert (colour == GUARDIAN) == rec.active[k], (k, colour, rec.active[k])
    # a second episode draws the static layer again, once
    _episode(env, rec, steps=3)
    assert len(calls) == rec.static_draws == 2


@pytest.mark.parametrize("env_id, coord", ENVS)
def test_the_path_is_coloured_by_who_was_in_control(envs, env_id, coord):
    env = envs(env_id)
    env.reset(seed=2)
    rec = EpisodeRecorder(env)
    rec.begin()
    view = rec.view
    win = _panel_window(view)
    s0 = rec.states[0].copy()
    n = 14
    xs = (win.x0 + win.x1) / 2 + np.linspace(-0.3, 0.3, n + 1) * (win.x1 - win.x0)
    states = np.repeat(s0[None, :], n + 1, axis=0)
    states[:, coord] = xs
    if env_id.startswith("Quadrotor"):
        states[:, 1] = (win.y0 + win.y1) / 2
        states[:, 2] = (view.side.y0 + view.side.y1) / 2
    elif coord == 0 and states.shape[1] >= 3 and not env_id.startswith("CartPole"):
        states[:, 1] = (win.y0 + win.y1) / 2
    if env_id.startswith(("CartPole", "Inverted")):
        states[:, view.g.ang] = 0.0
    rec.states[0] = states[0]
    flags = [False] + [k >= n // 2 for k in range(1, n + 1)]
    for k in range(1, n + 1):
        rec.add(states[k], flags[k], 0.1 * k, outcome="collision" if k == n else None)
    frame = rec.frame()
    pix = view.path_pixels(states)
    for k in range(2, n - 2):  # away from the body at the end
        for p in range(pix.shape[1]):
            x, y = ((pix[k - 1, p] + pix[k, p]) / 2).round().astype(int)
            want = GUARDIAN if flags[k] else DRIVER
            assert tuple(frame[y, x]) == want, (k, p, tuple(frame[y, x]), want)
    # the collision point is marked on the last frame
    x, y = pix[n, 0].round().astype(int)
    assert tuple(frame[y + 5, x + 5]) == COLLISION
    # an earlier frame shows the path so far only, and no collision mark
    early = rec.frame(n // 2)
    x, y = ((pix[n - 3, 0] + pix[n - 2, 0]) / 2).round().astype(int)
    assert tuple(early[y, x]) not in (GUARDIAN, DRIVER)
    # frames asked out of order equal frames asked in order
    assert np.array_equal(rec.frame(n), frame)


def test_the_recorder_refuses_before_begin_and_outside_the_episode(envs):
    env = envs("Dubins4DParallel-v0")
    rec = EpisodeRecorder(env)
    with pytest.raises(RuntimeError, match="begin"):
        rec.frame()
    env.reset(seed=1)
    rec.begin()
    with pytest.raises(IndexError, match="frames 0-0"):
        rec.frame(3)


def test_signal_groups_share_a_scale_by_their_first_word():
    assert signal_groups(["risk", "risk_threshold", "barrier_min", "qp_fallbacks", "value"]) == {
        "risk": ["risk", "risk_threshold"],
        "barrier": ["barrier_min"],
        "qp": ["qp_fallbacks"],
        "value": ["value"],
    }


class _Lamp:
    """A simulator of one's own (the snapshot protocol) that renders: a lamp moved by its speed."""

    dt = 0.25
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self):
        self.x = 0.0

    def get_state(self):
        return np.array([self.x])

    def set_state(self, state):
        self.x = float(state[0])

    def step(self, action):
        self.x += self.dt * float(action[0])
        return abs(self.x) >= 5.0

    def render(self, state):
        frame = np.zeros((4, 8, 3), dtype=np.uint8)
        frame[:, int(np.clip(state[0] + 4, 0, 7))] = 255
        return frame


def _lamp_env(**kw):
    from rmm_envs.envs.any_env import guarded

    return guarded(
        _Lamp(),
        driver=lambda obs: np.array([0.1], np.float32),
        safe_default=np.array([0.0], np.float32),
        success=lambda obs: False,
        max_episode_sim_time=10.0,
        **kw,
    )


def test_an_env_without_a_view_of_its_own_shows_its_render_frame():
    from rmm_envs.views import EnvFrameView

    env = _lamp_env(render_mode="rgb_array")
    view = view_for(env, 256)
    assert isinstance(view, EnvFrameView)
    rec = EpisodeRecorder(env, view)
    _episode(env, rec, steps=12)
    assert rec.frame_size == (128 + rec.strip_height, 256)
    for k in (6, 7):
        f = rec.frame(k)
        assert f.shape == (*rec.frame_size, 3)
        assert tuple(f[2, 100]) == (GUARDIAN if rec.active[k] else DRIVER)  # the frame's border
    assert rec.active[7] and not rec.active[6]
    with pytest.raises(ValueError, match="render_mode='rgb_array'"):
        view_for(_lamp_env())


# ---------------------------------------------------------------------- the guardians' signals()


def _guardian(name: str):
    from rmm_guardians import make_guardian

    if name == "hj":
        from rmm_guardians.hj.grid import Grid

        grid = Grid([-15.0, -15.0, -np.pi, 0.0], [15.0, 15.0, np.pi, 2.0], [25, 25, 12, 7], periodic=[2])
        return make_guardian("hj", grid=grid, cache=False)
    return make_guardian(name, env_id="Dubins4DGuarded-v0")


def _decisions(name: str, env_id: str, call_signals: bool, steps: int = 40):
    env = gym.make(env_id, clock="fixed:5")
    g = (
        _guardian(name)
        if env_id.startswith("Dubins4D")
        else __import__("rmm_guardians").make_guardian(name, env_id=env_id)
    )
    obs, info = env.reset(seed=11)
    u = env.unwrapped
    g.reset(
        seed=11,
        observation_space=env.observation_space,
        action_space=env.action_space,
        privileged=u.privileged if g.privileged else None,
    )
    actions, signals = [], []
    for _ in range(steps):
        a = g.act(obs, info)
        if call_signals:
            signals.append(g.signals())
        actions.append((int(a["active_ctrl"]), np.concatenate([np.ravel(v) for k, v in sorted(a.items())])))
        obs, _, term, trunc, info = env.step(a)
        if term or trunc:
            break
    env.close()
    return actions, signals


@pytest.mark.parametrize(
    "name, env_id, keys",
    [
        ("lrmm", "Dubins4DGuarded-v0", {"risk", "risk_threshold"}),
        ("cbf", "Dubins4DGuarded-v0", {"barrier_min", "qp_fallbacks"}),
        ("hj", "Dubins4DGuarded-v0", {"value", "value_threshold"}),
        ("cbf", "Dubins3DMazeGuarded-v0", {"barrier_min", "qp_fallbacks"}),
        ("hj", "Dubins3DMazeGuarded-v0", {"value", "value_threshold"}),
        ("hj", "QuadrotorRoomGuarded-v0", {"value", "value_threshold"}),
    ],
)
def test_signals_have_the_documented_keys_and_never_change_a_decision(name, env_id, keys):
    with_signals, signals = _decisions(name, env_id, True)
    without, _ = _decisions(name, env_id, False)
    assert len(with_signals) == len(without)
    for (a1, u1), (a2, u2) in zip(with_signals, without, strict=True):
        assert a1 == a2 and np.array_equal(u1, u2)
    assert signals and all(set(s) == keys for s in signals)
    assert all(isinstance(v, float) and math.isfinite(v) for s in signals for v in s.values())


def test_the_maze_hj_value_is_the_grid_value_at_the_pose_decided_on():
    """Hand check of the maze ``hj`` signal: the value interpolated at the car's pose (read
    from the env's own state), the look-ahead rule's band as the line."""
    from rmm_guardians import make_guardian

    env = gym.make("Dubins3DMazeGuarded-v0", clock="fixed:5")
    g = make_guardian("hj", env_id="Dubins3DMazeGuarded-v0")
    before = g.signals()
    assert set(before) == {"value", "value_threshold"} and all(math.isnan(v) for v in before.values())  # nothing known
    obs, info = env.reset(seed=3)
    u = env.unwrapped
    g.reset(seed=3, observation_space=env.observation_space, action_space=env.action_space, privileged=u.privileged)
    g.act(obs, info)
    d = g.delegate
    x, y, psi = (float(v) for v in u.privileged()["state"][:3])
    psi = (psi + math.pi) % (2 * math.pi) - math.pi
    expected = float(d.grid.interp_many([d.V], np.array([x, y, psi, d.speed]))[0])
    assert g.signals() == {"value": expected, "value_threshold": float(d.band)}
    env.close()


def test_a_guardian_without_signals_gives_none():
    from rmm_guardians import make_guardian

    assert make_guardian("brakes").signals() == {}


# ---------------------------------------------------------------------- the views' geometry against the worlds' own checks


def _static(env, size: int = 256):
    """The view of ``env`` (after ``reset``), its world and its static layer ``(H, W, 3)``."""
    from PIL import Image, ImageDraw

    view = view_for(env, size)
    world = view.world(env)
    img: Image.Image = view.new_picture()
    view.draw_static(ImageDraw.Draw(img), world)
    return view, world, np.asarray(img)


def _centres(win: Window, k: int = 1) -> np.ndarray:
    """World points ``(k H, k W, 2)`` at the centres of the window's pixels (``k = 1``), or of a
    ``k x k`` grid inside each pixel (``k`` odd: the middle one is the pixel's centre)."""
    c, r = np.meshgrid(np.arange(win.width * k), np.arange(win.height * k))
    x = win.x0 + (c + 0.5) / k * (win.x1 - win.x0) / win.width
    y = win.y1 - (r + 0.5) / k * (win.y1 - win.y0) / win.height
    return np.stack([x, y], axis=-1)


def _panel(img: np.ndarray, win: Window) -> np.ndarray:
    return img[win.top : win.top + win.height, win.left : win.left + win.width]


def _grow(mask: np.ndarray, k: int) -> np.ndarray:
    """``mask`` dilated by a ``(2k+1)^2`` square."""
    pad = np.pad(mask, k)
    out = np.zeros_like(mask)
    for dy in range(2 * k + 1):
        for dx in range(2 * k + 1):
            out |= pad[dy : dy + mask.shape[0], dx : dx + mask.shape[1]]
    return out


def _is(img: np.ndarray, *colours) -> np.ndarray:
    return np.any([(img[..., :3] == c).all(axis=-1) for c in colours], axis=0)


def _assert_drawn_where_inside(
    inside, win: Window, drawn: np.ndarray, tol: int = 2, ignore=None, what: str = "", k: int = 3, least: int = 20
) -> None:
    """Every pixel whose centre ``inside`` (the world's own check: world points ``(N, 2)`` ->
    ``(N,)`` bool) puts in a shape is drawn (``drawn``: the panel's ``(H, W)`` bool), and every
    pixel outside is not, except within ``tol`` pixels of a shape's border (and ``ignore``).
    The border is found on a grid of ``k x k`` points per pixel: two shapes that nearly touch
    leave a sliver between them thinner than a pixel."""
    pts = _centres(win, k)
    fine = np.asarray(inside(pts.reshape(-1, 2)), bool).reshape(pts.shape[:2])
    centre = fine[k // 2 :: k, k // 2 :: k]
    deep_in = ~_grow(~fine, k * tol)[k // 2 :: k, k // 2 :: k] & centre
    deep_out = ~_grow(fine, k * tol)[k // 2 :: k, k // 2 :: k] & ~centre
    edge = np.ones_like(centre)  # the world beyond the panel's edge is not sampled: leave tol pixels there
    edge[tol:-tol, tol:-tol] = False
    ignore = edge if ignore is None else ignore | edge
    deep_in, deep_out = deep_in & ~ignore, deep_out & ~ignore
    assert deep_in.sum() >= least, f"{what}: too few pixels inside to compare ({deep_in.sum()})"
    missing, extra = np.argwhere(deep_in & ~drawn), np.argwhere(deep_out & drawn)
    assert len(missing) == 0, f"{what}: {len(missing)} pixels inside not drawn, e.g. (row, col) {missing[:5].tolist()}"
    assert len(extra) == 0, f"{what}: {len(extra)} pixels outside drawn, e.g. (row, col) {extra[:5].tolist()}"


def _assert_body_at(img: np.ndarray, centre, radius_px: float, colours, what: str = "") -> None:
    """The picture holds a filled disc of ``radius_px`` in ``colours`` centred at pixel ``centre``
    (within 1.5 px: a disc drawn off by more leaves a pixel 1.5 px inside its border bare)."""
    cx, cy = centre
    r = np.arange(int(cy - radius_px) - 2, int(cy + radius_px) + 3)
    c = np.arange(int(cx - radius_px) - 2, int(cx + radius_px) + 3)
    cc, rr = np.meshgrid(c, r)
    # Pillow's pixel k is drawn for coordinates in [k, k + 1): its centre is at k + 1/2
    d = np.hypot(cc + 0.5 - cx, rr + 0.5 - cy)
    core = d <= radius_px - 1.5
    assert core.sum() >= 5, what
    ok = _is(img[rr[core], cc[core]], *colours)
    assert ok.all(), f"{what}: body pixels missing around {centre}: {np.argwhere(~ok)[:5].tolist()}"


_BODY = (DRIVER, GUARDIAN, BODY_OUTLINE)


def _car_body_check(env, view, world, what: str) -> None:
    from PIL import ImageDraw

    state = view.state(env)
    pic = view.new_picture()
    view.draw_body(ImageDraw.Draw(pic), state, False, world)
    w = view.window
    assert np.allclose(view.path_pixels(state[None])[0, 0], w.px(state[0], state[1]))
    r_px = max(view.body_radius, 5.0 / w.scale) * w.scale
    _assert_body_at(np.asarray(pic), w.px(state[0], state[1]), r_px, _BODY, what)


@pytest.mark.parametrize("generator", ["rectangular", "honeycomb"])
def test_the_maze_view_draws_the_walls_of_the_collision_check_and_the_car_where_it_is(generator):
    env = gym.make("Dubins3DMazeGuarded-v0", clock="fixed:5", render_mode="rgb_array")
    options = None if generator == "rectangular" else {"maze": {"generator": "honeycomb", "rows": 10, "cols": 10}}
    env.reset(seed=3, options=options)
    for _ in range(150):  # the driver alone (the drive where a wall seemed to be drawn too long)
        _, _, term, trunc, _ = env.step(env.action_space.inactive())
        if term or trunc:
            break
    view, world, img = _static(env, 512)
    maze = env.unwrapped.privileged()["maze"]
    side = max(maze.width, maze.height)
    w = view.window
    assert (w.x0, w.x1, w.y0, w.y1) == (0.0, side, 0.0, side)  # the env's own frame's window
    walls = _is(img, WALL)
    _assert_drawn_where_inside(lambda p: maze.point_clearance(p) <= 0, w, walls, tol=1, what=f"maze {generator}", k=1)
    _car_body_check(env, view, world, f"maze {generator}")
    # the env's own frame: the car's disc (blue, drawn last) is centred at the same pixel
    frame = env.render()
    ys, xs = np.nonzero(_is(frame, (31, 119, 180)))
    assert (
        np.hypot(xs.mean() + 0.5 - w.px(*view.state(env)[:2])[0], ys.mean() + 0.5 - w.px(*view.state(env)[:2])[1]) < 1.0
    )
    # and its walls agree with the view's but for their borders (the env grows them by 2 px of the maze)
    # (away from what each draws over the walls: the env its car, goal and route, the view its goal)
    covered = _grow(_is(frame, (31, 119, 180), (44, 160, 44), (170, 170, 170)) | _is(img, GOAL), 2)
    env_walls = _is(frame, (0, 0, 0))

    def in_env_frame(p):  # the env frame's pixel of each point (its window is the view's, same size)
        col = np.clip((p[:, 0] / side * frame.shape[1]).astype(int), 0, frame.shape[1] - 1)
        row = np.clip(((side - p[:, 1]) / side * frame.shape[0]).astype(int), 0, frame.shape[0] - 1)
        return env_walls[row, col]

    _assert_drawn_where_inside(in_env_frame, w, walls, ignore=covered, what="maze vs env frame", k=1)
    env.close()


@pytest.mark.parametrize(
    "env_id", ["Dubins4DParallel-v0", pytest.param("Dubins4DMapParallel-v0", marks=_needs("pymunk"))]
)
def test_the_dubins4d_views_draw_the_obstacles_of_the_collision_check_and_the_car_where_it_is(env_id):
    env = gym.make(env_id, clock="fixed:5")
    for seed in (4,):  # seed 4: the goal overlaps an obstacle
        env.reset(seed=seed)
        view, world, img = _static(env, 512)
        scene = env.unwrapped.scene
        w = view.window
        if env_id.startswith("Dubins4DMap"):  # the env's own frame: the map and its start box, 5% margin
            box = np.vstack([scene.map.bounding_box(), np.asarray(scene.map.start_box, float)])
            c, half = (box.min(0) + box.max(0)) / 2, 0.525 * float(np.max(box.max(0) - box.min(0)))
            assert np.allclose([w.x0, w.x1, w.y0, w.y1], [c[0] - half, c[0] + half, c[1] - half, c[1] + half])
        else:
            assert (w.x0, w.x1, w.y0, w.y1) == (-15.0, 15.0, -15.0, 15.0)
        # the map's world answers point by point (pymunk): one point per pixel there
        k = 1 if env_id.startswith("Dubins4DMap") else 3
        _assert_drawn_where_inside(scene.state_failed, w, _is(img, OBSTACLE), what=f"{env_id} seed {seed}", k=k)
        # the goal under the obstacles, as the env's frame draws it: a goal disc may overlap an obstacle
        gx, gy, gr = world.goal[:3]

        def in_goal(p, gx=gx, gy=gy, gr=gr, failed=scene.state_failed):
            return (np.hypot(p[:, 0] - gx, p[:, 1] - gy) <= gr) & ~failed(p)

        ring = ~in_goal(_centres(w).reshape(-1, 2)).reshape(w.height, w.width)  # the ring around it: not compared
        _assert_drawn_where_inside(in_goal, w, _is(img, GOAL), tol=1, ignore=ring, what=f"{env_id} goal", k=k, least=1)
        _car_body_check(env, view, world, env_id)
    env.close()


def _convex_projection(obj: dict, pts: np.ndarray, axis: int) -> np.ndarray:
    """``(N,)`` bool: points ``(N, 2)`` of the plane without ``axis`` (z: top, y: side) lie in the
    shape's projection along ``axis`` (its signed distance, minimised over that axis, is <= 0)."""
    from rmm_envs.systems.quadrotor.rooms import bounding_radius
    from rmm_envs.systems.quadrotor.rotations import quat_to_rot

    pos, R, size = np.asarray(obj["pos"], float), quat_to_rot(np.asarray(obj["quat"], float)), np.asarray(obj["size"])
    reach = bounding_radius(obj["shape"], size)
    best = np.full(pts.shape[0], np.inf)
    keep = [i for i in range(3) if i != axis]
    for t in np.linspace(pos[axis] - reach, pos[axis] + reach, 41):
        p = np.empty((pts.shape[0], 3))
        p[:, keep], p[:, axis] = pts, t
        q = (p - pos) @ R  # R^T (p - pos), row by row
        if obj["shape"] == "box":
            e = np.abs(q) - size
            sd = np.linalg.norm(np.maximum(e, 0), axis=1) + np.minimum(e.max(axis=1), 0)
        elif obj["shape"] == "cylinder":
            e = np.stack([np.hypot(q[:, 0], q[:, 1]) - size[0], np.abs(q[:, 2]) - size[1] / 2], axis=1)
            sd = np.linalg.norm(np.maximum(e, 0), axis=1) + np.minimum(e.max(axis=1), 0)
        else:
            sd = np.linalg.norm(q, axis=1) - size[0]
        best = np.minimum(best, sd)
    return best <= 0


@_needs("pybullet")
def test_the_quadrotor_views_draw_the_rooms_boxes_and_objects_and_the_body_where_it_is(envs):
    from PIL import ImageDraw

    from rmm_envs.systems.quadrotor.rooms import bounding_radius
    from rmm_envs.systems.quadrotor.view import BODY_RADIUS, FLOOR, OBJECT_EDGE, OBJECT_FILL, WALL_FILL

    env = envs("QuadrotorRoomParallel-v0")
    env.reset(seed=4)
    view, world, img = _static(env, 256)
    room = env.unwrapped.privileged()["room"]
    lo, hi = room.bounds()
    top, side = view.top, view.side
    assert top.x0 <= lo[0] and top.x1 >= hi[0] and top.y0 <= lo[1] and top.y1 >= hi[1]  # the room fits
    assert side.y0 <= 0.0 and side.y1 >= hi[2]
    # the discs of the goal and of the waypoints (rings) and the captions are drawn over the rest
    marks = np.vstack([world.waypoints, world.goal[None, :3]])
    for win, axes, panel_name in ((top, (0, 1), "top"), (side, (0, 2), "side")):
        pts = _centres(win)
        pan = _panel(img, win)
        ignore = np.zeros(pts.shape[:2], bool)
        ignore[:18, :100] = True  # the caption
        for m in marks:
            ignore |= np.hypot(pts[..., 0] - m[axes[0]], pts[..., 1] - m[axes[1]]) <= world.goal_radius + 4 / win.scale

        def in_objects(p, axes=axes, along=2 if panel_name == "top" else 1):
            out = np.zeros(p.shape[0], bool)
            for obj in room.objects:
                c, r = np.asarray(obj["pos"], float), bounding_radius(obj["shape"], obj["size"])
                near = (np.abs(p[:, 0] - c[axes[0]]) <= r) & (np.abs(p[:, 1] - c[axes[1]]) <= r)
                out[near] |= _convex_projection(obj, p[near], along)
            return out

        drawn = _is(pan, OBJECT_FILL, OBJECT_EDGE)
        _assert_drawn_where_inside(in_objects, win, drawn, ignore=ignore, what=f"{panel_name} objects", k=1)
        if panel_name == "top":  # the walls' boxes seen from above; from the side they are outlined only

            def in_walls(p):
                c = np.asarray(room.walls, float)
                return (
                    (np.abs(p[:, None, 0] - c[None, :, 0]) <= c[None, :, 3])
                    & (np.abs(p[:, None, 1] - c[None, :, 1]) <= c[None, :, 4])
                ).any(axis=1)

            _assert_drawn_where_inside(in_walls, win, _is(pan, WALL_FILL), ignore=ignore, what="top walls", k=1)
        else:  # the floor, z = 0
            row = int(side.px(0.0, 0.0)[1])
            assert _is(img[row, side.left + 5 : side.left + side.width - 5], FLOOR).mean() > 0.9
    # the body: a disc of the body's radius at (x, y) above and at (x, z) from the side
    state = view.state(env)
    pic = view.new_picture()
    view.draw_body(ImageDraw.Draw(pic), state, True, world)
    pix = view.path_pixels(state[None])[0]
    assert np.allclose(pix, [top.px(state[0], state[1]), side.px(state[0], state[2])])
    _assert_body_at(np.asarray(pic), pix[0], BODY_RADIUS * top.scale, _BODY, "top body")
    r_side = BODY_RADIUS * min(side.scale, side.height / (side.y1 - side.y0))
    _assert_body_at(np.asarray(pic), pix[1], r_side, _BODY, "side body")


@pytest.mark.parametrize(
    "env_id", ["CartPoleParallel-v0", pytest.param("InvertedPendulumParallel-v0", marks=_needs("mujoco"))]
)
def test_the_pole_views_draw_the_envs_limits_and_the_cart_and_pole_where_they_are(envs, env_id):
    from PIL import ImageDraw

    from rmm_envs.views.base import OBSTACLE

    env = envs(env_id)
    env.reset(seed=3)
    view, world, img = _static(env)
    g, u = view.g, env.unwrapped
    sim = u.env.unwrapped
    state = view.state(env)
    if env_id.startswith("CartPole"):
        assert (g.x_limit, g.angle_limit, g.length) == (sim.x_threshold, sim.theta_threshold_radians, 2 * sim.length)
        assert np.allclose(state[[g.pos, g.ang]], np.asarray(sim.state)[[0, 2]])
    else:
        import mujoco

        model = sim.model
        pole = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "cpole")
        assert np.allclose(model.jnt_range[0], [-g.x_limit, g.x_limit])  # the rail's ends
        assert math.isclose(2 * model.geom_size[pole][1], g.length, rel_tol=1e-4)
        assert np.allclose(state[[g.pos, g.ang]], sim.data.qpos[:2])
        # the env's own termination: the pole beyond angle_limit
        keep = (sim.data.qpos.copy(), sim.data.qvel.copy())
        ends = []
        for a in (g.angle_limit - 0.01, g.angle_limit + 0.01):
            sim.set_state(np.array([0.0, a]), np.zeros(2))
            ends.append(sim.step(np.zeros(1))[2])
        sim.set_state(*keep)
        assert ends == [False, True]
    w = view.window
    for s in (-1, 1):  # the track's ends marked red at the limit, not beyond
        x, y = w.px(s * g.x_limit, 0.0)
        assert _is(img[int(y), int(x)], OBSTACLE)
        x, y = w.px(s * (g.x_limit + 0.1), 0.0)
        assert not _is(img[int(y), int(x)], OBSTACLE)
    # the cart at x, the pole's tip at length (sin, cos) of its angle, the failing angles red
    st = state.copy()
    st[g.pos], st[g.ang] = 0.4 * g.x_limit, 0.5 * g.angle_limit
    pic = view.new_picture()
    view.draw_body(ImageDraw.Draw(pic), st, False, world)
    pic_a = np.asarray(pic)
    x, th = st[g.pos], st[g.ang]
    tip = (x + g.length * math.sin(th), g.length * math.cos(th))
    assert np.allclose(view.path_pixels(st[None])[0, 0], w.px(*tip))
    for px in (w.px(x, 0.0), w.px(x + 0.2, 0.0), w.px(x - 0.2, 0.0), w.px(*tip)):
        assert _is(pic_a[int(px[1]), int(px[0])], *_BODY), px
    assert not _is(pic_a[int(w.px(x + 0.35, 0.0)[1]), int(w.px(x + 0.35, 0.0)[0])], *_BODY)
    for a in (-g.angle_limit, g.angle_limit):
        px = w.px(x + 0.8 * g.length * math.sin(a), 0.8 * g.length * math.cos(a))
        near = pic_a[int(px[1]) - 1 : int(px[1]) + 2, int(px[0]) - 1 : int(px[0]) + 2]
        assert _is(near, OBSTACLE).any(), a
