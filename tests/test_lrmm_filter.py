"""lrmm's hand-back rule: the one-step prediction that rates the driver's control, the
``RatedDriver`` and ``Restart`` strategies on hand-built risk sequences, the driver's control
read from ``info`` and every bad-input path."""

import math
import warnings

import numpy as np
import pytest

from rmm_envs.autonomy import ObservationLayout
from rmm_envs.machine_independent import wrap_angle
from rmm_envs.systems.dubins4d.env import CONTROLS, observation_layout
from rmm_guardians.lrmm.decision import decision_path, read_decision, set_decision
from rmm_guardians.lrmm.guardian import LRMMGuardian
from rmm_guardians.lrmm.model import LRMMModel
from rmm_guardians.lrmm.nominal import PredictRater, make_rater
from rmm_guardians.lrmm.strategies import BrakeTurn, Commit, MovingAverage, RatedDriver, Restart, SafestCandidate
from tests.test_lrmm import SPACES, env_spaces, forward_ray_model, obs_with

D4 = observation_layout(12)
D4_LOW = np.array([0, -np.inf, -np.inf, -np.pi, 0] + [0] * 12, float)
D4_HIGH = np.array([np.inf, np.inf, np.inf, np.pi, 2] + [10] * 12, float)
QUAD = ObservationLayout.of(
    ("rays", 8),
    ("rays_vertical", 2),
    ("orientation", 4),
    ("velocity", 3),
    ("angular_velocity", 3),
    ("goal_offset", 3),
    ray_angles=[k * math.pi / 4 for k in range(8)],
)
QUAD_CONTROLS = ("vforward_ctrl", "vleft_ctrl", "vup_ctrl", "yawrate_ctrl")


def d4_obs(speed=1.0, heading=0.5, rays=None):
    rays = np.arange(12, dtype=float) if rays is None else np.asarray(rays, float)
    return np.concatenate([[3.0, 4.0, -2.0, heading, speed], rays])


def test_dubins_prediction_moves_speed_heading_and_rays_by_hand():
    r = PredictRater(D4, CONTROLS, 1.0, D4_LOW, D4_HIGH)
    x = d4_obs()
    step = 2 * math.pi / 12  # one ray
    y = r.predict(x, (step, 0.5))  # turn left by exactly one ray, speed up by 0.5 m/s
    assert y[:3].tolist() == [3.0, 4.0, -2.0]  # time and goal offset unchanged
    assert y[3] == pytest.approx(0.5 + step) and y[4] == 1.5
    assert y[5:].tolist() == [float((k + 1) % 12) for k in range(12)]  # ray k now reads what ray k+1 read
    half = r.predict(x, (-step / 2, 0.0))  # half a ray to the right: the mean of the two neighbours
    assert half[5:].tolist() == pytest.approx([(k + (k - 1) % 12) / 2 for k in range(12)])
    assert r.predict(x, (0.0, -0.5))[4] == 0.5
    assert r.predict(d4_obs(speed=0.2), (0.0, -0.5))[4] == 0.0  # clipped to the observation's speed range
    assert r.predict(d4_obs(speed=1.8), (0.0, 0.5))[4] == 2.0
    wrapped = r.predict(d4_obs(heading=3.0), (0.25, 0.0))[3]
    assert wrapped == pytest.approx(3.25 - 2 * math.pi)  # the heading stays in [-pi, pi)
    assert r.predict(x, (0.0, 0.0)).tolist() == x.tolist()  # holding nothing predicts the observation


def test_quadrotor_prediction_replaces_the_measured_velocity_with_the_command():
    x = np.arange(23, dtype=float)
    r = make_rater(QUAD_CONTROLS, QUAD, 1.0, np.full(23, -np.inf), np.full(23, np.inf))
    y = r.predict(x, (1.5, -0.5, 0.25, 0.7))
    assert y[14:17].tolist() == [1.5, -0.5, 0.25]
    assert np.delete(y, [14, 15, 16]).tolist() == np.delete(x, [14, 15, 16]).tolist()  # nothing else moves


def test_no_rater_without_a_layout_or_a_field_it_predicts():
    assert make_rater(CONTROLS, None, 1.0, D4_LOW, D4_HIGH) is None
    assert make_rater(CONTROLS, D4, None, D4_LOW, D4_HIGH) is None  # no hold time: a model without a head
    rays_only = ObservationLayout.of(("rays", 4), ray_angles=[0, 1, 2, 3])  # uneven rays, no speed
    assert make_rater(CONTROLS, rays_only, 1.0, np.zeros(4), np.ones(4)) is None


def speed_model(cand_bias=(0.0, -2.0, -1.0)):
    """Unit 0 = sigmoid(4 v - 4) of the speed v (a stopped car: 0.018, 1 m/s: 0.5, 1.5 m/s: 0.881);
    the candidates' units are constants sigmoid(cand_bias): brake-left 0.5, brake-right 0.119,
    accelerate 0.269 by default."""
    W0 = np.zeros((1, 17))
    W0[0, 4] = 4.0
    W1 = np.array([[1.0], [0.0], [0.0], [0.0]])
    meta = {
        "env_id": "Dubins4DCircles-v0",
        "obs_dim": 17,
        "features": list(range(17)),
        "hidden": [1],
        "activation": "relu",
        "output_bias": True,
        "candidates": [[-0.25, -0.5], [0.25, -0.5], [0.0, 0.5]],
        "candidate_hold": 1.0,
    }
    return LRMMModel([(W0, np.array([0.0])), (W1, np.array([-4.0, *cand_bias]))], np.zeros(17), np.ones(17), meta)


def at(speed):
    o = obs_with(10.0, 10.0, 10.0)
    o[4] = speed
    return o


def driver(a, turn=0.0):
    return {"nominal_control": np.array([turn, a])}


def rated(threshold, margin=0.0, commit=0, **kw):
    """The former ``trigger="driver"`` rule: RatedDriver, then Commit, then the head's safest candidate."""
    g = LRMMGuardian(
        speed_model(),
        threshold=threshold,
        strategies=(RatedDriver(margin=margin, **kw), Commit(commit), SafestCandidate()),
    )
    g.reset(seed=0, **SPACES)
    return g


def test_driver_trigger_keeps_the_driver_while_its_own_control_is_rated_safe():
    g = rated(0.5, margin=0.1)
    assert math.isnan(g.signals()["risk_driver"])  # nothing rated yet
    # at 1 m/s the state risk is 0.5; braking predicts 0.5 m/s (rated 0.119): the driver's control is kept
    assert g.act(at(1.0), driver(-0.5))["active_ctrl"] == 0
    assert g.signals()["risk_driver"] == pytest.approx(1 / (1 + math.exp(2)))
    assert g.signals()["risk"] == pytest.approx(0.5) and g.signals()["risk_threshold"] == 0.5
    # accelerating predicts 1.5 m/s, rated 0.881, 0.76 above the best candidate rated alike: the guardian
    # takes control with the safest candidate of the head (brake-right, 0.119)
    a = g.act(at(1.0), driver(0.5))
    assert (a["active_ctrl"], a["turnrate_ctrl"][0], a["accel_ctrl"][0]) == (1, 0.25, -0.5)
    # the same state without RatedDriver acts on the state risk alone (0.5 is not above 0.5; 0.45 is)
    r = LRMMGuardian(speed_model(), threshold=0.45, strategies="SafestCandidate")
    r.reset(seed=0, **SPACES)
    assert r.act(at(1.0), driver(-0.5))["active_ctrl"] == 1
    assert "risk_driver" not in r.signals()


def test_driver_trigger_hand_back_sequence_with_commit_and_margin():
    g = rated(0.5, margin=0.1, commit=2)
    accels = [0.5, -0.5, -0.5, -0.5, -0.5, 0.5, -0.5]
    assert [g.act(at(1.0), driver(u))["active_ctrl"] for u in accels] == [1, 1, 1, 0, 0, 1, 1]
    # a margin larger than the risk the best candidate saves (0.881 - 0.119): the guardian never acts
    lazy = rated(0.5, margin=0.77, commit=2)
    assert [lazy.act(at(1.0), driver(u))["active_ctrl"] for u in accels] == [0] * 7
    # the margin decides when to take control, not when to hand back: at 1 m/s holding the speed is rated
    # 0.5, above the threshold 0.15 but only 0.38 above the best candidate
    hold = rated(0.15, margin=0.5)
    assert [hold.act(at(1.0), driver(u))["active_ctrl"] for u in (0.0, 0.5, 0.0, 0.0, -0.5, 0.0)] == [0, 1, 1, 1, 0, 0]
    # at the threshold is safe: 1.0 m/s predicted exactly (0.5 m/s + 0.5), rated 0.5
    edge = rated(0.5)
    assert edge.act(at(0.5), driver(0.5))["active_ctrl"] == 0
    assert edge.signals()["risk_driver"] == 0.5
    # the composition order of the former rule matters: a Commit before RatedDriver is overruled by it
    late = LRMMGuardian(
        speed_model(), threshold=0.5, strategies=(Commit(2), RatedDriver(margin=0.1), SafestCandidate())
    )
    late.reset(seed=0, **SPACES)
    assert [late.act(at(1.0), driver(u))["active_ctrl"] for u in accels] == [1, 0, 0, 0, 0, 1, 0]


def test_restart_accelerates_a_slow_car_when_that_candidate_is_safe_enough():
    # candidates: brake-left 0.5, brake-right 0.119 (the safest), accelerate 0.269
    g = LRMMGuardian(speed_model(), threshold=0.3, strategies="SafestCandidate, Commit(steps=3), Restart(speed=0.3)")
    g.reset(seed=0, **SPACES)
    fast, slow = at(1.5), at(0.2)  # state risks 0.881 and 0.039
    steps = [g.act(o, {}) for o in (fast, fast, slow, slow, slow, slow)]
    assert [(a["active_ctrl"], float(a["accel_ctrl"][0])) for a in steps] == [
        (1, -0.5),
        (1, -0.5),
        (1, 0.5),
        (1, 0.5),
        (1, 0.5),
        (0, 0.0),
    ]  # brakes, then restarts, then hands back
    # accelerate (0.269) is above the threshold 0.25
    strict = LRMMGuardian(
        speed_model(), threshold=0.25, strategies="SafestCandidate, Commit(steps=1), Restart(speed=0.3)"
    )
    strict.reset(seed=0, **SPACES)
    assert [float(strict.act(o, {})["accel_ctrl"][0]) for o in (fast, slow)] == [-0.5, -0.5]
    off = LRMMGuardian(speed_model(), threshold=0.3, strategies="SafestCandidate, Commit(steps=1)")  # no Restart
    off.reset(seed=0, **SPACES)
    assert [float(off.act(o, {})["accel_ctrl"][0]) for o in (fast, slow)] == [-0.5, -0.5]
    # the car must be slower than the speed: Restart(speed=0.2) leaves a car at 0.2 m/s braking
    edge = LRMMGuardian(speed_model(), threshold=0.3, strategies="SafestCandidate, Commit(steps=1), Restart(speed=0.2)")
    edge.reset(seed=0, **SPACES)
    assert [float(edge.act(o, {})["accel_ctrl"][0]) for o in (fast, slow)] == [-0.5, -0.5]


def test_missing_nominal_control_falls_back_to_the_state_risk_with_one_warning():
    g = rated(0.45)
    with pytest.warns(UserWarning, match=r"info\['nominal_control'\].*state risk"):
        assert g.act(at(1.0), {})["active_ctrl"] == 1  # state risk 0.5 > 0.45
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per guardian
        assert g.act(at(0.5), {"sim_time": 0.0})["active_ctrl"] == 0
        assert g.act(at(1.0), driver(-0.5))["active_ctrl"] == 0  # given again: the driver's control decides


@pytest.mark.parametrize(
    "bad", [np.array([0.1]), np.array([0.1, float("nan")]), np.zeros((2, 2)), "fast", [0.0, float("inf")]]
)
def test_malformed_nominal_control_is_named(bad):
    g = rated(0.5)
    with pytest.raises(ValueError, match=r"info\['nominal_control'\] must be 2 finite numbers"):
        g.act(at(1.0), {"nominal_control": bad})


def test_bad_hand_back_options_are_named():
    m = speed_model()
    for strategies, match in (
        (
            "RatedDriver(trigger='always')",
            r"unexpected keyword argument 'trigger'.*its parameters: margin, still, stay",
        ),
        ("RatedDriver(margin=-0.1)", r"RatedDriver margin must be a finite number >= 0.0, got -0.1"),
        ("Restart(speed=float('nan'))", r"arguments must be literals"),
        ((Restart,), "strategies must be Strategy objects or spec strings"),  # the class, not an object
    ):
        with pytest.raises(ValueError, match=match):
            LRMMGuardian(m, threshold=0.5, strategies=strategies)
    with pytest.raises(ValueError, match=r"Restart speed must be a finite number >= 0.0, got nan"):
        Restart(speed=float("nan"))
    # RatedDriver and Restart compare with or pick among the head's candidates: on a model without a head
    # they are refused when the guardian is built, naming the head
    for strategies in ("RatedDriver, SafestCandidate", "BrakeTurn, Restart(speed=0.2)"):
        with pytest.raises(ValueError, match=r"reads the model's action-conditioned head \('candidates'\).*has none"):
            LRMMGuardian(forward_ray_model(), threshold=0.5, strategies=strategies)
    # the former refusal of trigger='driver' with hysteresis is gone: both are strategies, run in order
    both = LRMMGuardian(m, threshold=0.5, strategies="RatedDriver, MovingAverage(window=4), SafestCandidate")
    assert both.strategies == (RatedDriver(), MovingAverage(window=4), SafestCandidate())
    W = [(np.zeros((1, 12)), np.zeros(1)), (np.zeros((4, 1)), np.zeros(4))]
    on_rays = LRMMModel(W, np.zeros(12), np.ones(12), {**m.meta, "obs_dim": 12, "features": list(range(12))})
    # the prediction moves fields it would not read
    rays_only = LRMMGuardian(on_rays, threshold=0.5, strategies="RatedDriver, SafestCandidate", inputs="rays")
    with pytest.raises(ValueError, match="strategy RatedDriver rates the driver's control"):
        rays_only.check_spaces(SPACES["observation_space"], SPACES["action_space"])


@pytest.mark.parametrize(
    "make",
    [
        lambda: RatedDriver(margin=True),
        lambda: RatedDriver(still=False),
        lambda: Restart(speed=True),
        lambda: Restart(speed="0.3"),
    ],
    ids=["margin-True", "still-False", "speed-True", "speed-str"],
)
def test_a_bool_or_a_string_is_no_number_of_a_strategy(make):
    with pytest.raises(ValueError, match="must be a"):
        make()


def test_restart_needs_a_speed_and_an_acceleration():
    lay = ObservationLayout.of(
        ("time", 1),
        ("goal_offset", 2),
        ("heading", 1),
        ("v", 1),
        ("rays", 12),
        ray_angles=[2.0 * math.pi * i / 12 for i in range(12)],
    )
    g = LRMMGuardian(speed_model(), threshold=0.5, strategies="SafestCandidate, Restart(speed=0.3)")
    with pytest.raises(ValueError, match="strategy Restart needs an 'accel_ctrl' control and a 'speed'"):
        g.reset(seed=0, **env_spaces(layout=lay))


def test_stored_hand_back_defaults_round_trip(tmp_path):
    p = speed_model().save(tmp_path / "m.npz")
    set_decision(p, 0.4, "RatedDriver(margin=0.05), Commit(steps=5), SafestCandidate", "a test")
    d = read_decision(decision_path(p))
    assert (d.threshold, d.strategies, d.chosen_by) == (
        0.4,
        "RatedDriver(margin=0.05, still=None, stay=True), Commit(steps=5), SafestCandidate()",
        {"how": "a test"},
    )
    g = LRMMGuardian(p)
    assert g.strategies == (RatedDriver(margin=0.05), Commit(steps=5), SafestCandidate())
    assert (g.strategies[0].margin, g.strategies[0].still, g.strategies[0].stay) == (0.05, None, True)
    # an argument overrides the file (here: edits it)
    assert LRMMGuardian(p, strategies="-RatedDriver").strategies == (Commit(steps=5), SafestCandidate())
    with pytest.raises(ValueError, match=r"unexpected keyword argument 'hold'.*its parameters: margin, still, stay"):
        set_decision(p, 0.4, "RatedDriver(hold=3)", "x")
    with pytest.raises(ValueError, match="Restart speed must be a finite number >= 0.0, got -1.0"):
        set_decision(p, 0.4, "Restart(speed=-1.0)", "x")
    from rmm_guardians.lrmm.decision import main as decision_main

    spec = "SafestCandidate, Commit(steps=18), Restart(speed=0.3)"
    assert decision_main([str(p), "--threshold", "0.3", "--strategies", spec, "--chosen-by", "t"]) == 0
    d = read_decision(decision_path(p))
    assert (d.threshold, d.strategies, d.chosen_by) == (
        0.3,
        "SafestCandidate(), Commit(steps=18), Restart(speed=0.3)",
        {"how": "t"},
    )
    bad = [str(p), "--threshold", "0.3", "--strategies", "RatedDriver(margin=-2)", "--chosen-by", "t"]
    assert decision_main(bad) == 2


def test_stored_hand_back_defaults_apply_only_to_the_rule_they_were_chosen_for(tmp_path):
    from rmm_guardians.lrmm.guardian import LRMMPaperGuardian

    p = speed_model().save(tmp_path / "m.npz")
    set_decision(p, 0.4, "RatedDriver(margin=0.05), Commit(steps=5), SafestCandidate, Restart(speed=0.3)", "a test")
    stored = (RatedDriver(margin=0.05), Commit(steps=5), SafestCandidate(), Restart(speed=0.3))
    assert LRMMGuardian(p).strategies == stored
    # brake-and-turn given: the stored composition is replaced whole, no candidates rated or accelerated with
    assert LRMMGuardian(p, strategies="BrakeTurn").strategies == (BrakeTurn(),)
    paper = LRMMPaperGuardian(p)
    assert (paper.strategies, paper.threshold) == ((BrakeTurn(),), 0.85)
    # the moving average is of the state risk: the driver's rating taken out, the rest kept
    averaged = LRMMGuardian(p, strategies="-RatedDriver, +MovingAverage(window=20)")
    assert averaged.strategies == (Commit(steps=5), SafestCandidate(), Restart(speed=0.3), MovingAverage(window=20))


def _restart_on(cands, controls=("turnrate_ctrl", "accel_ctrl"), **kw):
    from types import SimpleNamespace

    r = Restart(**kw)
    g = SimpleNamespace(
        candidates=np.asarray(cands, float),
        observation_space=SimpleNamespace(layout=D4),
        action_space=SimpleNamespace(controls=controls),
    )
    r.reset(g)
    return r


def _decide(speed, cand_risks, threshold=0.4):
    from rmm_guardians.lrmm.strategies import DecisionContext

    step = DecisionContext(threshold)
    step.observation = d4_obs(speed=speed)
    step.out = np.array([0.9, *cand_risks])
    return step


def test_restart_turn_turns_a_stopped_car_in_place_and_keeps_its_side():
    # candidates: brake straight, brake turning left, brake turning right, accelerate straight
    cands = [[0.0, -0.5], [-0.25, -0.5], [0.25, -0.5], [0.0, 0.5]]
    kept = [0.0, -0.5]  # the control before Restart (SafestCandidate's: brake straight, rated 0.05)
    r = _restart_on(cands, speed=0.3, turn=True)
    # accelerating rated 0.9 > 0.4: turn where it stands, on the lower-rated side (right, 0.2)
    assert r.act(_decide(0.1, [0.05, 0.3, 0.2, 0.9]), kept).tolist() == [0.25, -0.5]
    # the left now rated lower: the side first chosen is kept (no dithering left and right)
    assert r.act(_decide(0.0, [0.05, 0.1, 0.2, 0.9]), kept).tolist() == [0.25, -0.5]
    # a way forward rated safe (0.3 <= 0.4): accelerate, and the side is forgotten
    assert r.act(_decide(0.0, [0.05, 0.1, 0.2, 0.3]), kept).tolist() == [0.0, 0.5]
    assert r.act(_decide(0.0, [0.05, 0.1, 0.2, 0.9]), kept).tolist() == [-0.25, -0.5]
    # a car at or above the speed: the control before it, turning or not
    assert r.act(_decide(0.3, [0.05, 0.1, 0.2, 0.9]), kept) is kept
    # without turn, the stopped car keeps the control before it (it would stay stopped)
    assert _restart_on(cands, speed=0.3).act(_decide(0.0, [0.05, 0.3, 0.2, 0.9]), kept) is kept


def test_restart_turn_keeps_stored_specs_and_names_what_it_needs():
    from rmm_guardians.lrmm.strategies import parse_strategies

    # the spec stored in decisions and run keys before turn existed is unchanged
    assert Restart(speed=0.3).spec() == "Restart(speed=0.3)" == Restart(speed=0.3, turn=False).spec()
    (back,) = parse_strategies(Restart(speed=0.7, turn=True).spec())
    assert back == Restart(speed=0.7, turn=True) != Restart(speed=0.7)
    assert back.clone().turn is True
    with pytest.raises(ValueError, match=r"Restart turn must be True or False, got 'yes'"):
        Restart(turn="yes")
    from types import SimpleNamespace

    g = SimpleNamespace(name="lrmm")
    actions = SimpleNamespace(controls=("accel_ctrl",))
    with pytest.raises(ValueError, match=r"Restart\(turn=True\) turns the car: it needs a 'turnrate_ctrl' control"):
        Restart(turn=True).check(g, SimpleNamespace(layout=D4), actions)
    Restart().check(g, SimpleNamespace(layout=D4), actions)  # without turn, no turn-rate control needed


def _predicted_one_by_one(r, x, u):
    """The prediction written out for one control in plain Python, as it was before it was batched:
    the reference ``predict_many`` must equal bit for bit (stored runs rated one control at a time
    replay unchanged)."""
    y = [float(v) for v in np.asarray(x, dtype=float)]
    for j, i in r.velocity:
        y[i] = float(u[j])
    if r.accel is not None:
        j, i, lo, hi = r.accel
        y[i] = min(max(y[i] + u[j] * r.hold, lo), hi)
    if r.turn is not None:
        j, h, r0, n = r.turn
        delta = u[j] * r.hold
        y[h] = float(wrap_angle(y[h] + delta))
        shift = delta * n / (2.0 * math.pi)
        old = [float(v) for v in x[r0 : r0 + n]]
        for k in range(n):
            f = k + shift
            lo_k = math.floor(f)
            w = f - lo_k
            y[r0 + k] = (1.0 - w) * old[lo_k % n] + w * old[(lo_k + 1) % n]
    return np.array(y)


@pytest.mark.parametrize("system", ["dubins4d", "dubins4d-hold-0.7", "quadrotor"])
def test_predicting_many_controls_at_once_is_predicting_each_bit_for_bit(system):
    """``rate_many`` predicts every control in one batch; each row must be the one-control
    prediction's numbers."""
    if system == "quadrotor":
        r, dim, box = make_rater(QUAD_CONTROLS, QUAD, 1.0, np.full(23, -np.inf), np.full(23, np.inf)), 23, [(-1, 1)] * 4
    else:
        hold = 0.7 if "0.7" in system else 1.0
        r, dim, box = PredictRater(D4, CONTROLS, hold, D4_LOW, D4_HIGH), 17, [(-0.25, 0.25), (-0.5, 0.5)]
    rng = np.random.default_rng(3)
    for _ in range(300):
        x = rng.uniform(-3.0, 10.0, dim).astype(np.float32)
        controls = [[rng.uniform(a, b) for a, b in box] for _ in range(8)]
        many = r.predict_many(x, controls)
        assert many.tobytes() == np.stack([_predicted_one_by_one(r, x, u) for u in controls]).tobytes()
        assert r.predict(x, controls[0]).tobytes() == many[0].tobytes()
