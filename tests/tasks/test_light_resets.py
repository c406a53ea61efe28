"""Light navigation resets (lac_rllib.tasks.light_resets): across several seeded resets our env
is bit-identical to safety_gymnasium's stock env, its models lack only the skybox, and an env
made for rendering keeps the stock path."""

import hashlib

import numpy as np
import pytest

from lac_rllib.tasks import get_task, safety_gym_compat

EPISODE = 40  # short episodes: the point is the resets between them


def _digest(rows) -> str:
    h = hashlib.sha256()
    for row in rows:
        for x in row:
            h.update(np.asarray(x, dtype=np.float64).tobytes())
    return h.hexdigest()


@pytest.mark.parametrize("task_id", ["SafetyPointGoal1-v0", "SafetyCarButton1-v0"])
def test_trajectories_across_resets_are_bit_identical_to_stock(task_id):
    sg = safety_gym_compat.apply()
    ours = get_task(task_id).make({"max_episode_steps": EPISODE})
    stock = sg.make(task_id, max_episode_steps=EPISODE)
    act_dim = ours.action_space.shape[0]
    rng = np.random.default_rng(3)
    rows_ours, rows_stock, layouts = [], [], set()
    for episode in range(3):  # seeded once: later layouts come from the env's own stream
        seed = 9 if episode == 0 else None
        o, _ = ours.reset(seed=seed)
        s, _ = stock.reset(seed=seed)
        rows_ours.append((o,))
        rows_stock.append((s.astype(np.float32),))
        layouts.add(tuple(np.round(ours.unwrapped.task.world_info.layout["goal"], 6)))
        done = False
        while not done:
            action = rng.uniform(-1, 1, size=act_dim).astype(np.float32)
            o, r, te, tr, info = ours.step(action)
            s, rew, cost, term, trunc, _ = stock.step(action.astype(np.float64))
            rows_ours.append((o, r, info["cost"], te, tr))
            rows_stock.append((s.astype(np.float32), rew, cost, term, trunc))
            done = te or tr
    assert len(layouts) == 3, "the resets did not re-place the layout"
    assert len(rows_ours) == 3 * (EPISODE + 1)
    assert _digest(rows_ours) == _digest(rows_stock)


def test_light_models_lack_only_the_skybox_and_rendering_or_opted_out_envs_keep_it():
    light = get_task("SafetyPointGoal1-v0").make()
    light.reset(seed=0)
    rendering = get_task("SafetyPointGoal1-v0").make({"render_mode": "rgb_array"})
    rendering.reset(seed=0)
    m_light, m_stock = light.unwrapped.task.model, rendering.unwrapped.task.model
    pixels = lambda m: [int(w) * int(h) for w, h in zip(m.tex_width, m.tex_height)]  # noqa: E731
    assert max(pixels(m_stock)) > 10**6, "the rendering env lost its skybox"
    off = get_task("SafetyPointGoal1-v0").make({"light_resets": False})
    off.reset(seed=0)
    assert pixels(off.unwrapped.task.model) == pixels(m_stock), "light_resets=False must keep the stock path"
    assert pixels(m_light)[0] == 6 and pixels(m_light)[1:] == pixels(m_stock)[1:]  # 1 pixel per cube face
    for field in ("body_pos", "body_quat", "body_mass", "body_invweight0", "dof_invweight0", "qpos0",
                  "geom_size", "geom_pos", "geom_rbound"):
        assert np.array_equal(getattr(m_light, field), getattr(m_stock, field)), field
    assert m_light.stat.meaninertia == m_stock.stat.meaninertia and m_light.stat.extent == m_stock.stat.extent
