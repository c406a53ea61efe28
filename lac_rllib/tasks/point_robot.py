"""The paper's Point robot on Safety-Gymnasium's Point tasks (``robot_variant: safety_gym``).

The paper trained on Safety-Gym, whose Point robot turns with a torque motor on its site
(openai/safety-gym@51ccec9, ``safety_gym/xmls/point.xml``: ``<motor gear="0 0 0 0 0 0.1"
site="robot" name="rz"/>``, the default force range ±0.05); Safety-Gymnasium's turns with a
velocity servo on its hinge (``<velocity gear="0.3" jointinparent="z" name="z"/>``), which does not
turn at all below a command of ~0.1 (docs/fidelity/README.md, benchmarks/point_turn.py). The two
robot files differ in that one actuator (and in colours, which nothing but a render reads).

``safety_gym`` builds every world of a Point task from Safety-Gymnasium's own ``point.xml`` with
that one line replaced (the site is named ``agent`` there): the rest of the task (layouts, lidar,
sensors, rewards, costs, the other actuator) is unchanged, and the action space is the same
([-1, 1]², the turn command second). The robot file is written once per process into a
temporary directory and the env's agent pointed at it before its first world is built.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

#: ``robot_variant``'s values: Safety-Gymnasium's Point (velocity servo) or Safety-Gym's (torque motor).
ROBOT_VARIANTS = ("safety_gymnasium", "safety_gym")
#: Safety-Gymnasium's turn actuator, and Safety-Gym's in its place.
SERVO = '<velocity gear="0.3" jointinparent="z" name="z"/>'
MOTOR = '<motor gear="0 0 0 0 0 0.1" site="agent" name="rz"/>'


def variant_xml() -> Path:
    """The Point robot file with Safety-Gym's torque motor (written once, named by its content)."""
    import safety_gymnasium

    stock = Path(safety_gymnasium.__file__).parent / "assets" / "xmls" / "point.xml"
    text = stock.read_text(encoding="utf-8")
    if text.count(SERVO) != 1:
        raise RuntimeError(f"{stock} has no single {SERVO!r}: not the safety_gymnasium 1.0.0 Point robot")
    text = text.replace(SERVO, MOTOR)
    digest = hashlib.sha256(text.encode()).hexdigest()[:12]
    path = Path(tempfile.gettempdir()) / "lac_rllib" / f"point_safety_gym_{digest}.xml"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)  # atomic: env runners in other processes may write it at once
    return path


def apply(env, variant: str) -> None:
    """Point ``env``'s robot (a stock Safety-Gymnasium Point env, before its first reset) at
    ``variant``'s file; "safety_gymnasium" leaves it as it is."""
    if variant not in ROBOT_VARIANTS:
        raise ValueError(f"robot_variant={variant!r}; accepted: {', '.join(ROBOT_VARIANTS)}")
    if variant == "safety_gym":
        env.unwrapped.task.agent.base = str(variant_xml())  # absolute: os.path.join keeps it
