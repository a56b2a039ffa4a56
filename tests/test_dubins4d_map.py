"""Dubins4DMapGuarded-v0 / Dubins4DMapParallel-v0: maps of your own on pymunk.

Agreement with the analytic circle world, hand-computed polygon and wall geometry, every bad
map, the reset options, labelling through the LabelledEnv protocol and the guardians' checks.
"""

import json
import math

import gymnasium as gym
import numpy as np
import pymunk  # noqa: E402,F401  (pinned in the test extra: a missing install fails here, it is not skipped)
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.risk import RiskEstimator
from rmm_envs.systems.dubins4d.circles import contact_params_each, points_in_circles, ray_cast
from rmm_envs.systems.dubins4d_map.env import Dubins4DMapEnv, example_map_path
from rmm_envs.systems.dubins4d_map.pymunk_world import PymunkWorld
from rmm_envs.systems.dubins4d_map.shape_map import MapError, load_map, triangulate


def circle_map(rng, k):
    return np.column_stack([rng.uniform(-10, 10, (k, 2)), rng.uniform(0.5, 4.0, k)])


def free_state(rng, circles, margin=1e-3):
    """A state whose position is clear of every circle by ``margin`` (no boundary ties)."""
    while True:
        s = np.array([rng.uniform(-12, 12), rng.uniform(-12, 12), rng.uniform(-np.pi, np.pi), rng.uniform(0, 2)])
        if not points_in_circles(s[None, :2], circles + [0, 0, margin])[0]:
            return s


# ------------------------------------------------------------------ agreement with the circle world
@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 7))
def test_world_queries_agree_with_the_analytic_circles(seed, k):
    rng = np.random.default_rng(seed)
    circles = circle_map(rng, k)
    w = PymunkWorld(load_map([{"circle": c.tolist()} for c in circles]))
    o = rng.uniform(-14, 14, (64, 2))
    h = rng.uniform(-np.pi, np.pi, 64)
    np.testing.assert_allclose(w.rays(o, h, 12, 10.0), ray_cast(o, h, circles, 12, 10.0), atol=1e-4)
    assert (w.points_inside(o) == points_in_circles(o, circles)).all()
    paths = o[:, None, :] + np.cumsum(rng.normal(0, 0.4, (64, 16, 2)), axis=1)
    want = contact_params_each(paths, np.repeat(circles[None], 64, axis=0)).min(axis=1)
    for got in (
        w.first_contacts(paths),
        np.concatenate([w.first_contacts(p[None]) for p in paths]),
    ):  # batch and one path
        assert (np.isfinite(got) == np.isfinite(want)).all()
        np.testing.assert_allclose(got[np.isfinite(want)], want[np.isfinite(want)], atol=1e-4)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5))
def test_circle_map_episode_equals_the_circle_env(seed, k):
    """The same obstacles as a map and as reset options: observations (rays), rewards and
    verdicts agree step for step under the same actions."""
    rng = np.random.default_rng(seed)
    circles = circle_map(rng, k)
    state = free_state(rng, circles)
    while True:
        goal = np.array([rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(0.1, 1.0)])
        if not points_in_circles(goal[None, :2], circles)[0] and math.hypot(*(goal[:2] - state[:2])) > goal[2] + 1e-3:
            break
    m = Dubins4DMapEnv(map=[{"circle": c.tolist()} for c in circles])
    c = gym.make("Dubins4DGuarded-v0").unwrapped
    om, _ = m.reset(seed=0, options={"state": state, "goal": goal})
    oc, _ = c.reset(seed=0, options={"state": state, "goal": goal, "obstacles": circles})
    np.testing.assert_allclose(om, oc, atol=1e-4)
    space = m.action_space
    for _ in range(60):
        a = space.inactive() if rng.random() < 0.5 else space.active(rng.uniform(space.control_low, space.control_high))
        om, rm, tm, trm, im = m.step(a)
        oc, rc, tc, trc, ic = c.step(a)
        np.testing.assert_allclose(om, oc, atol=1e-4)
        assert (rm, tm, trm) == (rc, tc, trc)
        if tm or trm:
            assert im["outcome"] == ic["outcome"]
            break


# ------------------------------------------------------------------ other shapes, by hand
def test_polygon_and_wall_rays_and_contacts_by_hand():
    # a U open to the right: outer [0, 4] x [0, 4], the notch [2, 4] x [1, 3] cut out
    u = [[0, 0], [4, 0], [4, 1], [2, 1], [2, 3], [4, 3], [4, 4], [0, 4]]
    w = PymunkWorld(load_map([{"polygon": u}, {"segment": [[10, -5], [10, 5], 0.4]}]))
    o = np.array([[-1.0, 2.0], [6.0, 2.0], [1.0, 2.0], [3.0, 2.0], [6.0, 0.5]])
    r = w.rays(o, np.zeros(5), n_rays=4, max_range=10.0)  # rays at 0, 90, 180, 270 degrees
    assert r[0, 0] == pytest.approx(1.0)  # to the U's outer left side at x = 0
    assert r[1, 0] == pytest.approx(10 - 0.2 - 6) and r[1, 2] == pytest.approx(
        4.0
    )  # the wall's face; the notch's back at x = 2
    assert r[2].tolist() == [0.0] * 4  # inside the U's left arm
    assert r[3].tolist() == pytest.approx(
        [10 - 0.2 - 3, 1.0, 1.0, 1.0]
    )  # in the notch: out through its mouth to the wall
    assert r[4, 2] == pytest.approx(2.0)  # along y = 0.5 into the lower arm's end at x = 4
    assert w.points_inside(
        np.array([[1, 1], [3, 2], [3, 0.5], [0, 0], [10.19, 0], [10.21, 0], [10, 5.19]])
    ).tolist() == [
        True,
        False,
        True,
        True,
        True,
        False,
        True,
    ]  # a corner counts; the wall is 0.2 m each side, its end rounded
    # straight paths at y = 2, 5 points 1 m apart: from x = -1.5 east, entering the U at x = 0 (segment 1,
    # s = 0.5); from x = 5.5 west through the notch to its back at x = 2 (segment 3, s = 0.5); in free space
    p1 = np.column_stack([np.linspace(-1.5, 2.5, 5), np.full(5, 2.0)])
    p2 = np.column_stack([np.linspace(5.5, 1.5, 5), np.full(5, 2.0)])
    p3 = np.column_stack([np.linspace(5, 8, 5), np.full(5, 2.0)])
    assert w.first_contacts(np.array([p1, p2, p3])).tolist() == pytest.approx([1.5, 3.5, math.inf])
    assert w.first_contacts(p2[None]).tolist() == pytest.approx([3.5])
    assert w.first_contacts(p1[2:][None]).tolist() == [0.0]  # starts inside


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(3, 14))
def test_triangulation_covers_random_simple_polygons_exactly(seed, n):
    rng = np.random.default_rng(seed)
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    if (
        np.min(np.diff(np.r_[ang, ang[0] + 2 * np.pi])) < 1e-3
        or np.max(np.diff(np.r_[ang, ang[0] + 2 * np.pi])) > np.pi - 1e-3
    ):
        return  # nearly repeated directions, or a star whose centre is outside: not a simple star polygon
    rad = rng.uniform(0.5, 5.0, n)
    poly = np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])
    m = load_map([{"polygon": poly[::-1].tolist()}])  # clockwise in: stored counter-clockwise
    tris = triangulate(m.polygons[0])
    areas = [0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])) for a, b, c in tris]
    area = 0.5 * float(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1]))
    assert min(areas) > 0 and sum(areas) == pytest.approx(area)
    # pymunk's inside test is the polygon's own (even-odd over its edges) at random points
    pts = rng.uniform(-5, 5, (200, 2))
    x, y = pts[:, :1], pts[:, 1:]
    a, b = poly, np.roll(poly, -1, axis=0)
    crosses = (a[None, :, 1] > y) != (b[None, :, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xs = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (b[None, :, 1] - a[None, :, 1])
    inside = (np.sum(crosses & (x < xs), axis=1) % 2) == 1
    assert (PymunkWorld(m).points_inside(pts) == inside).all()


# ------------------------------------------------------------------ the map format
@pytest.mark.parametrize(
    "entries, index, says",
    [
        ([{"circle": [0, 0, 1]}, {"square": [0, 0, 1]}], 1, "unknown shape 'square'"),
        (
            [{"polygon": [[0, 0], [2, 2], [2, 0], [0, 2]]}],
            0,
            "edges 0 ([0.0, 0.0] to [2.0, 2.0]) and 2 ([2.0, 0.0] to [0.0, 2.0]) cross",
        ),
        (
            [{"circle": [0, 0, 1]}, {"polygon": [[0, 0], [4, 0], [4, 4], [2, 0], [0, 4]]}],
            1,
            "cross or touch",
        ),  # a vertex on an edge
        ([{"polygon": [[0, 0], [2, 0], [1, 0], [1, 1]]}], 0, "fold"),
        ([{"polygon": [[0, 0], [1, 1], [2, 2]]}], 0, "edges 0 and 2 overlap"),  # all on a line
        ([{"polygon": [[0, 0], [1, 0], [1, 0], [0, 1]]}], 0, "vertices 1 and 2 are the same point"),
        ([{"polygon": [[0, 0], [1, 0]]}], 0, "at least 3"),
        ([{"circle": [0, 0, float("nan")]}], 0, "finite"),
        ([{"segment": [[0, 0], [1, float("inf")], 0.2]}], 0, "finite"),
        ([{"circle": [0, 0, 1]}, {"circle": [0, 1]}], 1, "expected [x, y, r]"),
        ([{"segment": [[0, 0], [1, 1]]}], 0, "expected [[x0, y0], [x1, y1], thickness]"),
        ([{"segment": [[0, 0], [1, 1], 0]}], 0, "thickness > 0"),
        ([{"circle": [0, 0, -1]}], 0, "r > 0"),
        ([{"circle": [0, 0, True]}], 0, "expected [x, y, r]"),
        ([{"circle": [0, 0, 1], "polygon": [[0, 0], [1, 0], [0, 1]]}], 0, "exactly one key"),
        ([{"circle": [0, 0, 1]}, {"goal": [5, 5, 1]}, {"goal": [6, 6, 1]}], 2, "at most one"),
        ([{"circle": [0, 0, 1]}, {"start": [[1, 1], [0, 2]]}], 1, "x_min < x_max"),
        ([{"circle": [0, 0, 1]}, 7], 1, "exactly one key"),
    ],
)
def test_bad_map_entries_are_named_by_index_and_content(entries, index, says):
    with pytest.raises(MapError) as e:
        load_map(entries)
    msg = str(e.value)
    assert f"entry {index} {json.dumps(entries[index])}" in msg and says in msg, msg
    assert isinstance(e.value, ValueError)


def test_bad_map_files_and_containers(tmp_path):
    with pytest.raises(MapError, match="has no obstacle"):
        load_map([])
    with pytest.raises(MapError, match="has no obstacle"):
        load_map([{"goal": [0, 0, 1]}, {"start": [[-1, -1], [1, 1]]}])
    with pytest.raises(MapError, match=r"map file '.*nope.json' cannot be read: FileNotFoundError"):
        load_map(tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text('[{"circle": [0, 0, 1]},]')
    with pytest.raises(MapError, match=r"map file '.*bad.json' is not valid JSON: .*line 1 column"):
        load_map(str(tmp_path / "bad.json"))
    with pytest.raises(MapError, match="expected a list of entries"):
        load_map(3.5)
    with pytest.raises(MapError, match="'shapes' must be a list"):
        load_map({"shapes": {"circle": [0, 0, 1]}})
    with pytest.raises(MapError, match=r"shapes\[1\] \{\"circle\": \[1, 2\]\}"):
        load_map({"shapes": [{"circle": [0, 0, 1]}, {"circle": [1, 2]}]})
    with pytest.raises(MapError, match="its goal .* centre inside an obstacle"):
        Dubins4DMapEnv(map=[{"circle": [0, 0, 2]}, {"goal": [0.5, 0, 1]}])
    with pytest.raises(MapError, match="unknown shape"):
        gym.make("Dubins4DMapGuarded-v0", map=[{"circle": [0, 0, 2]}, {"box": [0, 0, 1]}])


def test_map_forms_round_trip(tmp_path):
    m = load_map(example_map_path())
    assert m.obstacle_shapes == ("circle", "polygon", "segment") and len(m.entries) == 6
    assert m.start_box.tolist() == [[-10, -10], [10, 10]] and m.goal is None
    again = load_map(m.to_json())
    assert again.to_json() == m.to_json()
    obj = load_map(
        {"shapes": [{"circle": [0, 0, 1]}, {"polygon": [[2, 0], [3, 0], [3, 1], [2, 0]]}], "goal": [5, 5, 0.5]}
    )
    assert obj.polygons[0].tolist() == [[2, 0], [3, 0], [3, 1]]  # the closing vertex dropped
    assert obj.start_box.tolist() == [[-1, -1], [5.5, 5.5]]  # the bounding box, goal included
    cw = load_map([{"polygon": [[0, 0], [0, 1], [1, 0]]}])
    assert cw.polygons[0].tolist() == [[1, 0], [0, 1], [0, 0]]  # stored counter-clockwise
    path = tmp_path / "m.json"
    path.write_text(json.dumps(m.to_json()))
    assert load_map(path).to_json() == m.to_json()


# ------------------------------------------------------------------ the env
@pytest.mark.parametrize("env_id", ["Dubins4DMapGuarded-v0", "Dubins4DMapParallel-v0"])
def test_check_env_and_the_contract(env_id):
    env = gym.make(env_id, clock="fixed:1")
    check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=4)
    assert obs.shape == (17,) and env.observation_space.contains(obs)
    space = env.unwrapped.action_space
    for _ in range(2000):
        obs, r, te, tr, info = env.step(space.inactive())
        if te or tr:
            break
    assert info["outcome"] in ("goal", "collision", "timeout") and info["episode_stats"]["n_env_steps"] >= 1


def test_reset_options_defaults_and_determinism():
    env = Dubins4DMapEnv()
    a, _ = env.reset(seed=11)
    g1 = env.scene.goal.copy()
    b, _ = env.reset(seed=11)
    assert np.array_equal(a, b) and np.array_equal(g1, env.scene.goal)
    for seed in range(20):  # starts and goals obey the rules
        env.reset(seed=seed)
        st_, g = env.true_state, env.scene.goal
        assert not env.world.points_inside(np.array([st_[:2], g[:2]])).any()
        assert math.hypot(*(st_[:2] - g[:2])) > g[2] and (np.abs(st_[:2]) <= 10).all()
    env.reset(seed=0, options={"state": [-9, -9, 7.0, 1.0], "goal": [9, 9, 0.5]})
    assert env.true_state.tolist() == pytest.approx([-9, -9, 7.0 - 2 * math.pi, 1.0]) and env.scene.goal.tolist() == [
        9,
        9,
        0.5,
    ]
    fixed = Dubins4DMapEnv(map=[{"circle": [0, 0, 2]}, {"goal": [5, 5, 1]}, {"start": [[-6, -6], [-3, -3]]}])
    for seed in range(5):
        fixed.reset(seed=seed)
        assert (
            fixed.scene.goal.tolist() == [5, 5, 1]
            and (-6 <= fixed.true_state[:2]).all()
            and (fixed.true_state[:2] <= -3).all()
        )
    bad = [
        ({"state": [0.5, -1.5, 0, 1]}, "inside an obstacle"),
        ({"goal": [0.5, -1.5, 1]}, "centre inside an obstacle"),
        ({"state": [-9, -9, 0, 3]}, "speed must be in"),
        ({"goal": [1, 2]}, "option 'goal' must be 3 finite numbers"),
        ({"state": [-9, -9, 0, 1], "goal": [-9, -9, 1]}, "already inside the goal"),
        ({"obstacles": []}, "unknown reset options"),
        ({"goal": [9, 9, 0]}, "radius must be > 0"),
    ]
    for options, says in bad:
        with pytest.raises(ValueError, match=says):
            env.reset(seed=0, options=options)
    boxed = Dubins4DMapEnv(map=[{"circle": [0, 0, 5]}, {"start": [[-1, -1], [1, 1]]}])
    boxed._MAX_DRAWS = 500  # (100,000 by default) the same refusal, sooner
    with pytest.raises(ValueError, match="too little free room"):
        boxed.reset(seed=0)


def test_risk_labelling_through_the_protocol():
    """RiskLabel and the estimator work on a map; on circles they give the circle env's labels."""
    from rmm_envs.risk.protocol import check_labelled_env
    from rmm_envs.wrappers import RiskLabel

    env = RiskLabel(gym.make("Dubins4DMapGuarded-v0"), branches=8, depth=2, seed=0)
    check_labelled_env(env)
    _, info = env.reset(seed=2)
    assert 0.0 <= info["risk"] <= 1.0 and info["risk_n_leaves"] >= 1
    base = env.unwrapped
    rng = np.random.default_rng(0)
    states = base.sample_states(rng, 50)
    assert not base.risk_scene().state_failed(states).any() and base.observe_states(states, rng).shape == (50, 17)
    # near the L-shaped polygon the tree sees the polygon: a fast state driving into it is risky
    into = np.array([[-4.0, 0.5, 0.0, 2.0]])  # 2 m left of the L's upright arm at x = -2, heading at it
    away = np.array([[-4.0, 0.5, np.pi, 0.0]])
    est = RiskEstimator(base.risk_scene(), branches=16, depth=2)
    assert est.estimate(into, np.random.default_rng(1)).risk[0] > est.estimate(away, np.random.default_rng(1)).risk[0]
    # circles only: the map scene's labels equal the analytic scene's, draw for draw
    circles = np.array([[0.0, 0.0, 3.0], [6.0, 2.0, 2.0]])
    m = Dubins4DMapEnv(map=[{"circle": c.tolist()} for c in circles])
    c = gym.make("Dubins4DGuarded-v0").unwrapped
    m.reset(seed=0, options={"state": [-5, 0, 0, 1], "goal": [9, 9, 0.5]})
    c.reset(seed=0, options={"state": [-5, 0, 0, 1], "goal": [9, 9, 0.5], "obstacles": circles})
    s = c.sample_states(np.random.default_rng(3), 64)
    lm = RiskEstimator(m.risk_scene(), branches=8, depth=2, leaf="heuristic").estimate(s, np.random.default_rng(5))
    lc = RiskEstimator(c.risk_scene(), branches=8, depth=2, leaf="heuristic").estimate(s, np.random.default_rng(5))
    np.testing.assert_allclose(lm.risk, lc.risk, atol=1e-4)
    assert lc.risk.min() < lc.risk.max()  # not a trivial set


def test_datagen_on_a_map(tmp_path):
    from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset

    generate(
        DatagenConfig(env_id="Dubins4DMapGuarded-v0", configs=2, samples_per_config=6, branches=4, depth=2, seed=1),
        tmp_path / "d",
        workers=1,
        progress=False,
    )
    ds = load_dataset(tmp_path / "d")
    assert len(ds) == 12 and ds.obs.shape == (12, 17) and np.all((ds.risk >= 0) & (ds.risk <= 1))


def test_privileged_guardians_on_maps(tmp_path, capsys):
    from rmm_bench.cli import main as bench_main
    from rmm_guardians import make_guardian

    env = Dubins4DMapEnv()
    assert env.action_space.obstacle_shapes == ("circle", "polygon", "segment")
    for name in ("cbf", "hj"):
        with pytest.raises(ValueError, match=f"guardian '{name}' models circular obstacles only.*polygon, segment"):
            make_guardian(name).check_spaces(env.observation_space, env.action_space)
    assert (
        bench_main(
            [
                "--env",
                "Dubins4DMapParallel-v0",
                "--agent",
                "cbf",
                "--episodes",
                "1",
                "--workers",
                "1",
                "--out",
                str(tmp_path),
                "--no-progress",
            ]
        )
        == 2
    )
    assert "models circular obstacles only" in capsys.readouterr().err
    # a map of circles only: cbf runs, on the map's circles
    circ = Dubins4DMapEnv(map=[{"circle": [0, 0, 3]}, {"circle": [5, 5, 2]}, {"start": [[-10, -10], [10, 10]]}])
    g = make_guardian("cbf")
    g.check_spaces(circ.observation_space, circ.action_space)
    obs, info = circ.reset(seed=0)
    g.reset(
        seed=0, observation_space=circ.observation_space, action_space=circ.action_space, privileged=circ.privileged
    )
    assert circ.privileged()["obstacles"].tolist() == [[0, 0, 3], [5, 5, 2]]
    for _ in range(30):  # cbf filters the map env's driver control, info["nominal_control"]
        obs, r, te, tr, info = circ.step(g.act(obs, info))
        if te or tr:
            break


def test_rmm_bench_runs_on_the_example_map(tmp_path):
    from rmm_bench.cli import main as bench_main

    assert (
        bench_main(
            [
                "--env",
                "Dubins4DMapParallel-v0",
                "--agent",
                "lrmm",
                "--episodes",
                "2",
                "--workers",
                "1",
                "--clock",
                "fixed:1",
                "--out",
                str(tmp_path),
                "--no-progress",
                "--no-figure",
            ]
        )
        == 0
    )


def test_render_draws_the_map():
    env = gym.make("Dubins4DMapGuarded-v0", render_mode="rgb_array")
    env.reset(seed=3)
    img = env.render()
    assert img.shape == (512, 512, 3)
    red = np.all(img == (214, 39, 40), axis=2).mean()
    assert 0.05 < red < 0.3  # the example's obstacles cover about an eighth of the window
