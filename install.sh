#!/usr/bin/env bash
# Installs lac-rllib into ./.venv (Python 3.11). The order matters (docs/dependencies.md, "Install order"):
#   1. torch==2.13.0 alone first: the CPU wheel; any looser spec pulls GBs of CUDA packages.
#   2. the package and its pins (ray[tune,rllib]==2.60.0, gymnasium[mujoco]==1.2.2, mujoco, ...).
#   3. safety-gymnasium==1.0.0 with --no-deps: its wheel pins gymnasium 0.28 / mujoco 2.3;
#      lac_rllib.tasks.safety_gym_compat makes it work on our stack instead.
set -euo pipefail
cd "$(dirname "$0")"
PYTHON=${PYTHON:-python3.11}
[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q torch==2.13.0
.venv/bin/python -m pip install -q -e ".[test]"
.venv/bin/python -m pip install -q --no-deps safety-gymnasium==1.0.0
.venv/bin/python -c "import lac_rllib.tasks, ray, torch; print('lac-rllib installed: torch', torch.__version__, '| ray', ray.__version__)"
