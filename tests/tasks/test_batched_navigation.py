"""The batched navigation env (lac_rllib/tasks/batched_navigation.py) equals stock Safety-Gymnasium
step for step on every id it runs (lac_rllib/tasks/navigation_equality.py), and the comparison
catches an error of one ulp; the array task layer equals safety_gymnasium's own expressions on
random inputs, and the formulas it avoids would not."""

import numpy as np
import pytest

from lac_rllib.tasks import navigation_layer as layer
from lac_rllib.tasks.navigation_equality import compare
from lac_rllib.tasks.safety_gym import make_batched, supports

IDS = [f"Safety{robot}{family}{level}-v0" for family in ("Goal", "Button", "Push") for robot in ("Point", "Car")
       for level in (0, 1, 2)]


@pytest.mark.parametrize("env_id", IDS)
def test_a_short_stream_equals_stock_across_resets(env_id):
    c = compare(env_id, num_envs=2, vector_steps=130, seed=0, max_episode_steps=40)
    assert c.identical, c.line()
    assert c.episodes == 6 and c.steps == 2 * 130 - 6  # ends at steps 40, 81 and 122, each then a reset step


@pytest.mark.parametrize("env_id", ["SafetyPointGoal1-v0", "SafetyPointGoal2-v0", "SafetyPointButton1-v0",
                                    "SafetyCarGoal2-v0"])
def test_goals_met_and_costs_paid_alike(env_id):
    """Longer streams where the goal is met and resampled (Point's actions steer to it) and the
    constraints are violated: hazards, vases touched and moving, gremlins, wrong buttons."""
    c = compare(env_id, num_envs=3, vector_steps=300, seed=0, max_episode_steps=100)
    assert c.identical, c.line()
    assert c.cost_steps > 0 and (c.goals > 0 or "Car" in env_id), c.line()


def test_an_error_of_one_ulp_in_a_distance_is_caught(monkeypatch):
    exact = layer.dist_xy
    monkeypatch.setattr(layer, "dist_xy", lambda points, agent: np.nextafter(exact(points, agent), np.inf))
    c = compare("SafetyPointGoal1-v0", num_envs=2, vector_steps=20, seed=0)
    assert not c.identical and c.mismatches[0] == (1, "reward")


def test_the_batched_ids_are_goal_button_and_push_of_point_and_car():
    ids = [f"{r}{t}" for r in ("Point", "Car", "Doggo") for t in ("Goal1", "Button2", "Push0", "Circle1", "Run0")
           if supports(r, t)]
    assert ids == ["PointGoal1", "PointButton2", "PointPush0", "CarGoal1", "CarButton2", "CarPush0"]
    with pytest.raises(ValueError, match="SafetyDoggoGoal1-v0.*no batched backend"):
        make_batched("SafetyDoggoGoal1-v0", 2)


def test_autoreset_is_gymnasiums_next_step():
    env = make_batched("SafetyPointGoal0-v0", 2, 3)
    env.reset(seed=1)
    a = np.zeros((2, 2), np.float32)
    for _ in range(2):
        assert not env.step(a)[3].any()
    assert env.step(a)[3].all()
    obs, reward, terminated, truncated, info = env.step(a)  # the reset step: first observations, reward 0
    assert (reward == 0).all() and not (terminated | truncated).any() and "cost" not in info
    env.close()


def _stock_ego(pos, agent_pos, agent_mat):
    return np.matmul(np.concatenate([pos[:2], [0]]) - agent_pos, agent_mat)[:2]  # BaseTask._ego_xy


def _random_frames(n, k, seed=0):
    rng = np.random.default_rng(seed)
    points, agent = rng.uniform(-3, 3, (n, k, 3)), rng.uniform(-3, 3, (n, 3))
    th = rng.uniform(0, 2 * np.pi, n)
    mat = np.zeros((n, 3, 3))
    mat[:, 0, 0], mat[:, 0, 1], mat[:, 1, 0], mat[:, 1, 1], mat[:, 2, 2] = np.cos(th), -np.sin(th), np.sin(th), \
        np.cos(th), 1
    return points, agent, mat + rng.normal(scale=1e-3, size=mat.shape)


def test_the_egocentric_vector_is_stocks_matmul_and_einsum_would_differ():
    points, agent, mat = _random_frames(400, 8)
    stock = np.array([[_stock_ego(p, agent[i], mat[i]) for p in points[i]] for i in range(len(points))])
    assert np.array_equal(layer.ego_xy(points, agent, mat), stock)
    world = np.concatenate([points[..., :2], np.zeros(points.shape[:2] + (1,))], -1) - agent[:, None]
    assert not np.array_equal(np.einsum("nki,nij->nkj", world, mat)[..., :2], stock)


def _stock_lidar(positions, agent_pos, agent_mat, bins=16, max_dist=3.0):
    obs = np.zeros(bins)  # BaseTask._obs_lidar_pseudo, alias on
    for pos in positions:
        z = complex(*_stock_ego(pos, agent_pos, agent_mat))
        dist, angle = np.abs(z), np.angle(z) % (np.pi * 2)
        size = (np.pi * 2) / bins
        b = int(angle / size)
        sensor = max(0, max_dist - dist) / max_dist
        obs[b] = max(obs[b], sensor)
        alias = (angle - size * b) / size
        obs[(b + 1) % bins] = max(obs[(b + 1) % bins], alias * sensor)
        obs[(b - 1) % bins] = max(obs[(b - 1) % bins], (1 - alias) * sensor)
    return obs


def test_the_pseudo_lidar_is_stocks_and_hypot_distances_would_differ():
    points, agent, mat = _random_frames(400, 10, seed=1)
    stock = np.array([_stock_lidar(points[i], agent[i], mat[i]) for i in range(len(points))])
    ego = layer.ego_xy(points, agent, mat)
    assert np.array_equal(layer.pseudo_lidar(ego, 16, 3.0, 1.0, True), stock)
    z = ego[..., 0] + 1j * ego[..., 1]
    assert (np.hypot(ego[..., 0], ego[..., 1]) != np.abs(z)).any()  # why the layer keeps np.abs of x + iy


def test_hazard_indicator_is_a_strictly_positive_sum():
    d = np.array([[0.2, 0.5], [0.1999999, 3.0], [0.3, 0.2000001]])
    assert layer.hazard_violation(d, 0.2).tolist() == [False, True, False]  # at dist == size the cost is 0


@pytest.mark.parametrize("env_id", ["SafetyPointPush1-v0", "SafetyCarPush2-v0"])
def test_a_box_pushed_into_the_goal_resamples_the_goal_alike(env_id):
    """Random actions rarely push the box home, so both sides get the box set onto the goal (its
    free joint's position, the same on both) and step on: the goal met, resampled, rewarded alike."""
    from gymnasium.vector import SyncVectorEnv

    from lac_rllib.tasks.safety_gym import make_env

    stock = SyncVectorEnv([lambda: make_env({"env_id": env_id}) for _ in range(2)])
    fast = make_batched(env_id, 2)
    stock.reset(seed=4)
    fast.reset(seed=4)
    for side in (stock.envs, fast.envs):
        for env in side:
            task = env.unwrapped.task
            joint = task.model.body("push_box").jntadr[0]
            adr = task.model.jnt_qposadr[joint]
            task.data.qpos[adr:adr + 2] = task.data.body("goal").xpos[:2]
    a = np.zeros((2, 2), np.float32)
    met = 0
    for _ in range(3):
        r1, r2 = stock.step(a), fast.step(a)
        for x, y in zip(r1[:4], r2[:4]):
            assert np.array_equal(x, y)
        assert set(r1[4]) == set(r2[4]) and all(np.array_equal(r1[4][k], r2[4][k]) for k in r1[4])
        met += int(r1[4].get("goal_met", np.zeros(2, bool)).sum())
    assert met == 2  # each env met its goal once, then had a new one
    stock.close()
    fast.close()


def test_lidars_of_several_groups_in_one_pass_equal_one_lidar_each():
    ego = np.random.default_rng(0).uniform(-3, 3, (50, 12, 2))
    for groups in ([slice(0, 3), slice(3, 3), slice(5, 12), slice(3, 5)], [slice(0, 3), slice(5, 12)]):
        for g, lidar in zip(groups, layer.pseudo_lidars(ego, groups, 16, 3.0, 1.0, True)):
            alone = layer.pseudo_lidar(ego[:, g], 16, 3.0, 1.0, True) if g.stop > g.start else np.zeros((50, 16))
            assert np.array_equal(lidar, alone)
