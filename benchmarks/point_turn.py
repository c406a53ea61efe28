"""How fast each Point robot turns for a constant turn command (docs/fidelity/README.md, "The
simulator"): Safety-Gymnasium's (a velocity servo) beside the paper's Safety-Gym Point (a torque
motor, ``robot_variant: safety_gym``: lac_rllib/tasks/point_robot.py), on the same task.

    python benchmarks/point_turn.py [--task SafetyPointGoal1-v0]

For each turn command u (the action's second coordinate, the first held at 0), 300 steps to settle,
then the mean and spread of the heading rate over 200 more (rad/s, the heading from the robot's
orientation matrix, the step's length from the env's own MuJoCo timestep and frame skip).
Safety-Gymnasium's servo gives each command its own rate and no turn at all below ~0.1; Safety-Gym's
motor (gear 0.1, force range ±0.05, hinge damping 0.005) turns at 20·u rad/s up to u = 0.05 and at
its saturated 1 rad/s beyond.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

COMMANDS = (0.05, 0.1, 0.2, 0.5, 1.0)


def heading_rates(task: str, commands=COMMANDS, settle: int = 300, steps: int = 200,
                  robot_variant: str = "safety_gymnasium") -> dict:
    """{u: (mean, std) of the heading rate in rad/s} under the constant action (0, u)."""
    import lac_rllib.tasks  # noqa: F401 (registers the tasks)
    from lac_rllib.tasks import get_task

    env = get_task(task).make({"robot_variant": robot_variant})
    inner = env.unwrapped.task
    rates = {}
    for u in commands:
        env.reset(seed=0)  # builds the MuJoCo world
        dt = inner.model.opt.timestep * inner.sim_conf.frameskip_binom_n
        action = np.array([0.0, u], dtype=np.float32)
        for _ in range(settle):
            env.step(action)
        yaw = []
        for _ in range(steps):
            env.step(action)
            mat = inner.agent.mat
            yaw.append(np.arctan2(mat[1, 0], mat[0, 0]))
        per_step = np.diff(np.unwrap(np.array(yaw))) / dt
        rates[u] = (float(per_step.mean()), float(per_step.std()))
    env.close()
    return rates


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", default="SafetyPointGoal1-v0")
    args = parser.parse_args(argv)
    from lac_rllib.tasks import get_task

    try:
        get_task(args.task)
    except ValueError as e:
        parser.exit(2, f"point_turn: error: {str(e).splitlines()[0][:300]}\n")
    servo, motor = heading_rates(args.task), heading_rates(args.task, robot_variant="safety_gym")
    print("| turn command | Safety-Gymnasium's Point (rad/s) | spread | Safety-Gym's Point (rad/s) | spread |\n"
          "|---:|---:|---:|---:|---:|")
    for u in servo:
        print(f"| {u:g} | {servo[u][0]:.3f} | {servo[u][1]:.3f} | {motor[u][0]:.3f} | {motor[u][1]:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
